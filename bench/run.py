"""ncfmu benchmarks, measured side by side in one run: ``python bench/run.py [--quick] [--json FILE]``.

Every comparison interleaves its contenders (A, B, A, B, ...) and reports medians, on the lathe_taper
system (``--quick``: the first pass only, 13 s of simulated time, which still runs SC1..SC4).

- servo_step_speedup       the Python servo stepper (ncfmu.servo.axis.ServoAxis, the specification) us/step /
                           the native ServoAxis FMU us/step through FMI (set inputs, doStep, get outputs)
                           from a C host (tests/native/fmi_host.c). Goal >= 20.
                           servo_step_speedup_via_ctypes: the same FMU driven from Python as ncfmu's master
                           drives it (FmuSlave, ctypes arrays bound once): what a Python master can see.
- speedup_vs_python_loop   the same controller and servo Python objects stepped directly in one loop with the
                           same step / ncfmu's master running the FMUs. Goal >= 3.
- fmi_overhead_ratio       its inverse (kept for the history in results-*.json).
- c_loop_speedup           ncfmu's master with its Python loop (Master(native=False)) / with its C loop
                           (cosim/loop.c, the default): what the loop outside Python gains.
- vs_fmpy_ssp_speedup      fmpy.ssp.simulation.simulate_ssp on the same .ssp / ncfmu's master. Goal >= 3.
- vs_libcosim_speedup      libcosim (libcosimpy) on the same .ssp / ncfmu's master. Goal >= 2.5.
- vs_ecos_speedup          ecos (ecospy, its step_until) on the same .ssp / ncfmu's master. Goal >= 1.
- sweep_overhead_pct       per-variant scheduling overhead (ship, schedule, return, write) in % of a short
                           variant's run (2 s of lathe_taper) on a started 1-worker cluster. Goal < 5.
- sweep_speedup_2_workers  a 16-variant sweep of whole lathe_taper cycles run serially / the same on a
                           2-worker dask LocalCluster, cluster start-up included. Goal >= 1.8.
- rtf_lathe                simulated seconds per wall-clock second of the full lathe_roughing cycle.
- limiter_lookup_ns        AreaLimiter region search at 10, 100, 1000, 10000 regions.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def direct_loop(system_name: str, stop_time: float) -> float:
    """The same controllers and servos as plain Python objects, stepped in one loop (Gauss-Seidel)."""
    from ncfmu.systems import MODELS, get_system
    system = get_system(system_name)
    objects = {c.name: MODELS[c.model](**c.parameters) for c in system.components}
    inputs = {name: type(obj).default_inputs() for name, obj in objects.items()}
    outputs = {name: obj.outputs() for name, obj in objects.items()}
    wiring = {name: [] for name in objects}
    for k in system.connections:
        wiring[k.end_element].append((k.end_connector, outputs[k.start_element], k.start_connector))
    order = [(objects[c.name], inputs[c.name], wiring[c.name]) for c in system.components]
    h = system.step_size
    n = int(round(stop_time / h))
    t0 = time.perf_counter()
    for i in range(n):
        t = i * h
        for obj, ins, wires in order:
            for port, src, name in wires:
                ins[port] = src[name]
            obj.step(t, h, ins)
    return time.perf_counter() - t0


def ncfmu_master(archive: Path, stop_time: float, native: bool = True) -> float:
    from ncfmu.project import OpenSystem
    with OpenSystem(archive) as opened:
        opened.master.native = native
        wall = opened.run(stop_time=stop_time).wall_time
        assert opened.master.loop_used == ("c" if native else "python")
        return wall


def fmpy_ssp(archive: Path, stop_time: float) -> float:
    from fmpy.ssp.simulation import simulate_ssp
    t0 = time.perf_counter()
    simulate_ssp(str(archive), stop_time=stop_time, step_size=1e-3)
    return time.perf_counter() - t0


def libcosim(archive: Path, stop_time: float) -> float:
    from ncfmu.cosim.libcosim import run_ssp
    return run_ssp(archive, stop_time).wall_time     # the simulate_until time inside libcosim's process


ECOS_SCRIPT = """
import sys, time
from ncfmu.cosim.ecos import import_ecospy
EcosSimulation = import_ecospy().EcosSimulation
with EcosSimulation(ssp_path=sys.argv[1], step_size=1e-3) as sim:
    sim.init(parameter_set="parameters")
    t0 = time.perf_counter()
    sim.step_until(float(sys.argv[2]) + 5e-4)
    print("WALL", time.perf_counter() - t0)
    sim.terminate()
"""


def ecos(archive: Path, stop_time: float) -> float:
    """ecos's stepping time (its own process; start-up and loading excluded, as for libcosim)."""
    import subprocess
    proc = subprocess.run([sys.executable, "-c", ECOS_SCRIPT, str(archive), repr(stop_time)], capture_output=True,
                          text=True, timeout=3600)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("WALL")]
    if not line:
        raise RuntimeError(f"ecos failed: {proc.stderr[-500:]}")
    return float(line[-1].split()[1])


def servo_steps_c_host(n: int) -> float:
    """Seconds for ``n`` 1 ms steps of the native FMU driven from C (tests/native/fmi_host.c): the FMI
    calls alone, without Python's ctypes in between."""
    import re
    import subprocess

    from fmpy import extract, read_model_description

    from ncfmu.fmi.builder import fmi_headers
    fmu = HERE.parent / "fmus" / "ServoAxis.fmu"
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(tmp) / "fmi_host"
        subprocess.run(["cc", "-O2", f"-I{fmi_headers()}", "-o", str(exe), str(HERE.parent / "tests" / "native" /
                        "fmi_host.c"), "-ldl"], check=True)
        md = read_model_description(str(fmu))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        folder = extract(str(fmu), unzipdir=str(Path(tmp) / "fmu"))
        proc = subprocess.run([str(exe), f"{folder}/binaries/linux64/ServoAxis.so", md.guid,
                               f"file://{folder}/resources", "1", str(n), str(vr["pos"]),
                               f"{vr['pos_cmd']}+=0.02", f"{vr['vel_ff']}=20.0"],
                              capture_output=True, text=True, check=True)
        return float(re.search(r"STEPPING (\S+)", proc.stdout).group(1))


def servo_steps(n: int) -> tuple[float, float]:
    """(Python stepper, native FMU through FMI) seconds for ``n`` 1 ms steps of a moving axis.

    The FMU is driven as ncfmu's master drives it (``ncfmu.cosim.fmu.FmuSlave``: fmi2SetReal of the inputs,
    fmi2DoStep, fmi2GetReal of the outputs, every step, on ctypes arrays bound once).
    """
    import numpy as np

    from ncfmu.cosim.fmu import FmuSlave, unpacked_fmu
    from ncfmu.servo.axis import ServoAxis
    unpacked = unpacked_fmu(HERE.parent / "fmus" / "ServoAxis.fmu")
    slave = FmuSlave(unpacked, "bench")
    slave.initialize(0.0, n * 1e-3)
    vr = {v.name: v.valueReference for v in unpacked.model_description.modelVariables}
    inputs, outputs = np.zeros(2), np.zeros(4)
    slave.bind("Real", inputs, [vr["pos_cmd"], vr["vel_ff"]], outputs,
               [vr["pos"], vr["vel"], vr["following_error"], vr["torque"]])
    t0 = time.perf_counter()
    for i in range(n):
        inputs[0], inputs[1] = 0.02 * i, 20.0
        slave.write_inputs()
        slave.do_step(i * 1e-3, 1e-3)
        slave.read_outputs()
    native = time.perf_counter() - t0
    slave.terminate()
    axis = ServoAxis()
    t0 = time.perf_counter()
    for i in range(n):
        axis.step(i * 1e-3, 1e-3, {"pos_cmd": 0.02 * i, "vel_ff": 20.0, "enable": True})
    python = time.perf_counter() - t0
    return python, native


def interleaved(contenders: dict, repeats: int) -> dict[str, float]:
    times = {k: [] for k in contenders}
    for _ in range(repeats):
        for name, fn in contenders.items():
            times[name].append(fn())
    return {k: statistics.median(v) for k, v in times.items()}


def sweep_speedup(quick: bool) -> tuple[float, float, float]:
    from ncfmu.batch import sweep
    vary = {"seq.block[1].Xd": [0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65],
            "seq.block[1].feed": [3.0, 4.0]}                      # 16 variants
    stop = 6.0 if quick else 50.0          # the full bench sweeps whole lathe_taper cycles
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        sweep("lathe_taper", vary, Path(tmp) / "serial", workers=0, stop_time=stop, progress=False)
        serial = time.perf_counter() - t0
        t0 = time.perf_counter()
        sweep("lathe_taper", vary, Path(tmp) / "dask", workers=2, stop_time=stop, progress=False)
        parallel = time.perf_counter() - t0
    return serial / parallel, serial, parallel


def sweep_overhead() -> tuple[float, float]:
    """(scheduling overhead, run time) per short variant, s: 48 variants of 2 s of lathe_taper on a started
    1-worker cluster (system already opened on the worker); overhead = elapsed - the variants' own wall time
    (the client's connection and the one scatter of the archive included, spread over the 48)."""
    from ncfmu.batch import local_cluster, sweep
    with local_cluster(1) as cluster, \
            tempfile.TemporaryDirectory() as tmp:
        address = cluster.scheduler_address
        sweep("lathe_taper", {"seq.block[1].Xd": [0.5]}, Path(tmp) / "warm", scheduler=address, stop_time=2.0,
              progress=False)
        values = [round(0.3 + 0.005 * i, 3) for i in range(48)]
        t0 = time.perf_counter()
        rows = sweep("lathe_taper", {"seq.block[1].Xd": values}, Path(tmp) / "run", scheduler=address,
                     stop_time=2.0, progress=False)
        elapsed = time.perf_counter() - t0
    work = sum(float(r["wall_time"]) for r in rows)
    return (elapsed - work) / len(rows), work / len(rows)


def main() -> dict:
    parser = argparse.ArgumentParser(description="ncfmu benchmarks (ratios measured side by side)")
    parser.add_argument("--quick", action="store_true", help="the first lathe_taper pass only (13 s simulated)")
    parser.add_argument("--json", default=None, help="also write the numbers to this JSON file")
    args = parser.parse_args()
    from ncfmu.project import build
    root = HERE.parent
    build(root)
    taper = root / "ssp" / "lathe_taper.ssp"
    stop = 13.0 if args.quick else 50.0
    repeats = 3 if args.quick else 5
    out: dict[str, object] = {"cores": os.cpu_count(), "quick": args.quick, "stop_time_s": stop}

    n_servo = 5000 if args.quick else 20000
    servo = [(*servo_steps(n_servo), servo_steps_c_host(n_servo)) for _ in range(repeats)]
    py_s, ctypes_s, c_s = (statistics.median(s[k] for s in servo) for k in range(3))
    out["servo_step_speedup"] = py_s / c_s
    out["servo_step_speedup_via_ctypes"] = py_s / ctypes_s
    out["servo_python_us"], out["servo_native_us"] = py_s / n_servo * 1e6, c_s / n_servo * 1e6
    out["servo_native_via_ctypes_us"] = ctypes_s / n_servo * 1e6

    t = interleaved({"master": lambda: ncfmu_master(taper, stop), "direct": lambda: direct_loop("lathe_taper", stop),
                     "master_python_loop": lambda: ncfmu_master(taper, stop, native=False)}, repeats)
    out["fmi_overhead_ratio"] = t["master"] / t["direct"]
    out["speedup_vs_python_loop"] = t["direct"] / t["master"]
    out["c_loop_speedup"] = t["master_python_loop"] / t["master"]
    out["master_s"], out["direct_s"], out["master_python_loop_s"] = t["master"], t["direct"], t["master_python_loop"]
    n_steps = stop / 1e-3
    out["master_us_per_step"], out["direct_us_per_step"] = t["master"] / n_steps * 1e6, t["direct"] / n_steps * 1e6
    out["master_python_loop_us_per_step"] = t["master_python_loop"] / n_steps * 1e6

    t2 = interleaved({"master": lambda: ncfmu_master(taper, stop), "fmpy": lambda: fmpy_ssp(taper, stop),
                      "libcosim": lambda: libcosim(taper, stop), "ecos": lambda: ecos(taper, stop)},
                     max(2, repeats - 2))
    out["vs_fmpy_ssp_speedup"] = t2["fmpy"] / t2["master"]
    out["vs_libcosim_speedup"] = t2["libcosim"] / t2["master"]
    out["vs_ecos_speedup"] = t2["ecos"] / t2["master"]
    out["fmpy_ssp_s"], out["libcosim_s"], out["ecos_s"] = t2["fmpy"], t2["libcosim"], t2["ecos"]

    speedup, serial, parallel = sweep_speedup(args.quick)
    out["sweep_speedup_2_workers"], out["sweep_serial_s"], out["sweep_2_workers_s"] = speedup, serial, parallel
    overhead, variant = sweep_overhead()
    out["sweep_overhead_per_variant_s"], out["sweep_short_variant_s"] = overhead, variant
    out["sweep_overhead_pct"] = 100.0 * overhead / variant

    if args.quick:
        out["rtf_lathe"] = 13.0 / ncfmu_master(root / "ssp" / "lathe_roughing.ssp", 13.0)
    else:
        out["rtf_lathe"] = 95.0 / ncfmu_master(root / "ssp" / "lathe_roughing.ssp", 95.0)

    import limiter_lookup
    sys.argv = [sys.argv[0]]
    out.update(limiter_lookup.main())

    goals = {"servo_step_speedup": (">=", 20), "speedup_vs_python_loop": (">=", 3), "vs_fmpy_ssp_speedup": (">=", 3),
             "vs_libcosim_speedup": (">=", 2.5), "vs_ecos_speedup": (">=", 1), "sweep_speedup_2_workers": (">=", 1.8),
             "sweep_overhead_pct": ("<=", 5)}
    print(f"\nncfmu benchmarks ({'quick' if args.quick else 'full'}, {out['cores']} cores), "
          "medians of interleaved runs")
    print(f"{'metric':28s} {'value':>10s}  goal")
    for key in ("servo_step_speedup", "speedup_vs_python_loop", "c_loop_speedup", "vs_fmpy_ssp_speedup",
                "vs_libcosim_speedup",
                "vs_ecos_speedup", "sweep_speedup_2_workers", "sweep_overhead_pct", "rtf_lathe"):
        goal = goals.get(key)
        mark = ""
        if goal:
            ok = out[key] <= goal[1] if goal[0] == "<=" else out[key] >= goal[1]
            mark = f"{goal[0]} {goal[1]}  {'met' if ok else 'NOT met'}"
        print(f"{key:28s} {out[key]:10.2f}  {mark}")
    print(f"  servo step: Python stepper {out['servo_python_us']:.1f} us; native FMU through FMI from C "
          f"{out['servo_native_us']:.2f} us, from Python via ctypes (ncfmu's FmuSlave) "
          f"{out['servo_native_via_ctypes_us']:.2f} us (speedup {out['servo_step_speedup_via_ctypes']:.1f})")
    print(f"  per 1 ms step: master {out['master_us_per_step']:.1f} us (its Python loop "
          f"{out['master_python_loop_us_per_step']:.1f} us), direct Python loop {out['direct_us_per_step']:.1f} us")
    print(f"  master {out['master_s']:.2f} s, direct {out['direct_s']:.2f} s, "
          f"fmpy simulate_ssp {out['fmpy_ssp_s']:.2f} s, "
          f"libcosim {out['libcosim_s']:.2f} s, ecos {out['ecos_s']:.2f} s, sweep serial {serial:.1f} s vs 2 workers "
          f"{parallel:.1f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    main()
