"""The learned plant outside parknss (layer L9): the chain as an FMI 2.0 co-simulation FMU
(:mod:`~parknss.export.fmu`, generated C from the artefact's weights) and one 10 ms step as
an ONNX graph (:mod:`~parknss.export.onnx_step`)."""
