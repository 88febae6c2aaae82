"""The paper's evaluation studies, ``parknss reproduce``, and the application runs that draw
figures and write files (Table II, the deployment fit, evaluate, rate, the actuator study,
the demo); sweeps run through the one executor, :mod:`parknss.executor`."""
