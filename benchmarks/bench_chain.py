"""Speed of the chain's 10 ms step, every implementation in one run, as ratios to real time.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_chain.py [CHAIN] [--steps N] [--json]

Replays the longest logged command stream of the default campaign and reports, for each
implementation, the median time per 10 ms step (of 7 repeats, 3 or 2 for the slow ones)
and the real-time factor 10 ms / step, both in wall time (what a user waits for; the
median and the best repeat) and in this thread's CPU time (what the step costs, less
inflated on a loaded machine, where the wall time measures the scheduler as much as the
step):

* ``c_fmu``: the generated C step inside the FMU's binary (``pk_run`` of
  binaries/linux64/parknss_chain.so over the whole stream, one call; portable SSE2 build);
* ``c_native``: the same C built for this machine (``NativeChain.run``, ``-march=native``,
  bit-identical results);
* ``c_native_many``: 16 chains stepped together by the C ``pk_step_many`` of that build
  (one ctypes call a sample, prepared arguments), time per chain-step;
* ``fmi2_dostep``: the same FMU through FMPy's FMI 2.0 ``doStep`` (10 ms), one call a step;
* ``python_native``: ``DeployedChain.step`` (the Plant protocol) with the generated C
  through ctypes (``engine="native"``);
* ``python_native_many``: 16 such plants stepped together by ``parknss.chain.deployed.
  step_many`` (one C call a sample, each NSS layer applied to all 16), time per plant-step;
* ``python_numpy``: ``DeployedChain.step`` with the NumPy twin (the reference
  implementation, the default engine);
* ``onnxruntime``: the ONNX step graph (``parknss export onnx``), one session run a step;
* ``pytorch``: the chain's torch rollout (``Chain.rollout``, one trial, per sample).

It also prints the largest difference, per output, between the native C and the NumPy
twin over the replay (the tests hold 1e-9).
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

from parknss.chain.ccode import OUTPUTS
from parknss.config import SHIPPED_CHAIN
from parknss.plant import Commands

CMDS = ("gear", "torque_cmd", "decel_cmd", "steer_cmd")


CPU: dict[str, float] = {}  # µs per step in this thread's CPU time, by name
BEST: dict[str, float] = {}  # µs per step, the best wall time of the repeats, by name


def _per_step(fn, n: int, repeats: int = 7, name: str | None = None) -> float:
    """Median over ``repeats`` of the wall time of fn() divided by n, in µs (the median CPU
    time of this thread in ``CPU[name]``, the best wall time in ``BEST[name]``: other
    processes only add wall time, so the best is the least inflated, timeit's rule)."""
    ts, cs = [], []
    for _ in range(repeats):
        c0, t0 = time.thread_time(), time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t0) / n)
        cs.append((time.thread_time() - c0) / n)
    if name:
        CPU[name] = float(np.median(cs) * 1e6)
        BEST[name] = float(np.min(ts) * 1e6)
    return float(np.median(ts) * 1e6)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("chain", nargs="?", default=str(SHIPPED_CHAIN))
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    import torch

    from parknss.chain import load_chain
    from parknss.export.fmu import export_fmu
    from parknss.export.onnx_step import chain_state, export_onnx
    from parknss.nss.campaigns import default_campaign

    torch.set_num_threads(1)
    tr = max(default_campaign(), key=lambda t: t.n)
    cm = tr.array(CMDS)[: a.steps]
    n = len(cm)
    x0, y0 = [tr["vx"][0], tr["yaw_rate"][0]], [tr["torque"][0], tr["brake_pressure"][0],
                                                   tr["steer"][0]]
    cmds = [Commands(int(r[0]), float(r[1]), float(r[2]), float(r[3])) for r in cm]
    res: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        fmu = export_fmu(Path(tmp) / "chain.fmu", a.chain).path
        onnx_path = export_onnx(Path(tmp) / "chain.onnx", chain_dir=a.chain).path
        lib_path = Path(tmp) / "fmu.so"
        lib_path.write_bytes(zipfile.ZipFile(fmu).read("binaries/linux64/parknss_chain.so"))
        lib = ctypes.CDLL(str(lib_path))
        lib.pk_size.restype = ctypes.c_size_t
        dp = ctypes.POINTER(ctypes.c_double)
        state = ctypes.create_string_buffer(lib.pk_size())
        c = np.ascontiguousarray(cm, dtype=np.float64)
        out = np.empty((n, 8))
        args = [(ctypes.c_double * k)(*v) for k, v in ((2, x0), (3, y0), (4, cm[0]))]

        def c_run():
            lib.pk_start(state, *args)
            lib.pk_run(state, c.ctypes.data_as(dp), ctypes.c_long(n), out.ctypes.data_as(dp))

        res["c_fmu"] = _per_step(c_run, n, name="c_fmu")

        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        md = read_model_description(str(fmu))
        unz = extract(str(fmu))
        slave = FMU2Slave(guid=md.guid, unzipDirectory=unz,
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName="b")
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        gears = cm[:, 0].astype(int).tolist()  # gear is an FMI Integer (vr 0)
        reals = cm[:, 1:].tolist()

        def fmi_run():
            for k in range(n):
                slave.setInteger([0], [gears[k]])
                slave.setReal([1, 2, 3], reals[k])
                slave.doStep(currentCommunicationPoint=k * 0.01, communicationStepSize=0.01)

        res["fmi2_dostep"] = _per_step(fmi_run, n, repeats=3, name="fmi2_dostep")
        slave.terminate()
        slave.freeInstance()

        nat = load_chain(a.chain, engine="native").stepper

        def native_run():
            nat.start(x0, y0, cm[0])
            nat.run(cm)

        res["c_native"] = _per_step(native_run, n, name="c_native")
        nat.start(x0, y0, cm[0])
        agree = np.max(np.abs(nat.run(cm) - _twin_replay(a.chain, cm, x0, y0)), axis=0)

        from parknss.chain.deployed import step_many

        k_many = 16
        many = [load_chain(a.chain, engine="native") for _ in range(k_many)]
        m_many = min(n, 500)
        cm_many = [np.ascontiguousarray(np.broadcast_to(r, (k_many, 4))) for r in cm[:m_many]]
        states = (ctypes.c_void_p * k_many)(*[p.stepper._addr for p in many])
        out_many = np.empty((k_many, 8))
        c_many = many[0].stepper._lib.pk_step_many

        def c_many_run():
            for p in many:
                p.reset()
            for r in cm_many:
                c_many(states, k_many, r.ctypes.data, out_many.ctypes.data)

        res["c_native_many"] = _per_step(c_many_run, m_many * k_many, name="c_native_many")

        def many_run():
            for p in many:
                p.reset()
            for cmd in cmds[:m_many]:
                step_many(many, [cmd] * k_many)

        res["python_native_many"] = _per_step(many_run, m_many * k_many,
                                              name="python_native_many")

        for engine in ("native", "numpy"):
            dep = load_chain(a.chain, engine=engine)

            def plant_run(dep=dep):
                dep.reset()
                for cmd in cmds:
                    dep.step(cmd)

            res[f"python_{engine}"] = _per_step(plant_run, n, 15 if engine == "native" else 3,
                                                name=f"python_{engine}")

        import onnxruntime as ort

        so = ort.SessionOptions()
        so.intra_op_num_threads = so.inter_op_num_threads = 1
        sess = ort.InferenceSession(str(onnx_path), so, providers=["CPUExecutionProvider"])
        dep = load_chain(a.chain)
        dep.start(x0, y0, cm[0])
        s0 = chain_state(dep.rt).astype(np.float32)
        c32 = cm.astype(np.float32)
        m = min(n, 1000)

        def ort_run():
            s = s0
            for k in range(m):
                s, _ = sess.run(None, {"state": s, "command": c32[k]})

        res["onnxruntime"] = _per_step(ort_run, m, repeats=3, name="onnxruntime")

        from parknss.chain.trials import rollout_trials

        sub = tr.__class__(tr.id, tr.maneuver, tr.repetition,
                           {k: np.asarray(v)[:m] for k, v in tr.channels.items()})
        res["pytorch"] = _per_step(lambda: rollout_trials(dep.chain, [sub]), m, repeats=2,
                                   name="pytorch")

    doc = {"chain": a.chain, "steps": n, "us_per_step": res,
           "real_time_factor": {k: 1e4 / v for k, v in res.items()},
           "cpu_us_per_step": CPU, "best_wall_us_per_step": BEST,
           "cpu_real_time_factor": {k: 1e4 / v for k, v in CPU.items()},
           "native_vs_numpy_max_abs": dict(zip(OUTPUTS, agree.tolist(), strict=True)),
           "load_average": os.getloadavg()[0],
           "specs": load_chain(a.chain).chain.specs()}
    if a.json:
        print(json.dumps(doc, indent=2))
        return
    print(f"one run, {n} steps; load average {doc['load_average']:.1f} on {os.cpu_count()} "
          "cores; wall and CPU time per 10 ms step")
    print(f"{'':19s} {'wall µs':>9s} {'x real':>7s} {'best x':>7s} {'CPU µs':>9s} "
          f"{'x real':>7s} {'/ FMU C':>8s} {'/ native C':>10s}  (wall: median and best of the "
          "repeats; ratios of CPU times)")
    for k, v in res.items():
        c = CPU[k]
        print(f"{k:19s} {v:9.2f} {1e4 / v:7.0f} {1e4 / BEST[k]:7.0f} {c:9.2f} {1e4 / c:7.0f} "
              f"{c / CPU['c_fmu']:8.2f} {c / CPU['c_native']:10.2f}")
    py = "python_native"
    print(f"the Python Plant step (native engine): {1e4 / CPU[py]:.0f}x real time in CPU time, "
          f"{1e4 / res[py]:.0f}x in median wall time, {1e4 / BEST[py]:.0f}x in the best "
          f"(goal: 250x); overhead over the C step {CPU[py] / CPU['c_native']:.2f}x")
    print("native C vs NumPy twin, largest difference: "
          + ", ".join(f"{k} {v:.1e}" for k, v in doc["native_vs_numpy_max_abs"].items()))
    print(f"chain {a.chain}: {doc['specs']}")


def _twin_replay(chain: str, cm: np.ndarray, x0, y0) -> np.ndarray:
    """The NumPy twin's (T, 8) outputs under the commands cm from (x0, y0)."""
    from parknss.chain import load_chain

    rt = load_chain(chain).rt
    rt.start(x0, y0, cm[0])
    rows = []
    for c in cm:
        act, st = rt.step(*c)
        rows.append([*act, *st, rt.gear])
    return np.array(rows)


if __name__ == "__main__":
    main()
