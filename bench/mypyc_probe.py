"""What mypyc would give the lathe's controllers: ``python bench/mypyc_probe.py [--compiled DIR] [--steps 3000]``.

A probe, not the build: it copies ``src/ncfmu`` to a temporary folder, compiles the modules the lathe's controllers
run (``MODULES``; mypyc, pinned with mypy in ``.ci/constraints.txt``) beside a pure copy, records the inputs each
controller of lathe_taper receives in the direct Python loop (``bench/run.py``'s, the controllers and the Python
servo steppers), replays them into each controller from both copies under callgrind (collection only inside the
replay loop) and prints the instructions a step, and whether the compiled controller gave the same outputs, step
for step, as the pure one recorded. ``--compiled DIR``: a copy compiled before (skips the ~95 s of CPU mypyc takes).

Not compiled: ``errors.py`` (mypyc cannot subclass the builtin exceptions), ``contour.py`` (a ClassVar read through
the class), ``feed.py`` and ``rs274.py`` (not on the lathe). mypyc needed one annotation: ``CycleController.AXES``
is a ``ClassVar`` (the subclasses redefine it).
"""

from __future__ import annotations

import argparse
import pickle
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
MODULES = ("ports", "controllers/base", "controllers/motion", "controllers/cycle", "controllers/panel",
           "controllers/sequencer", "controllers/limiter", "controllers/geometry", "controllers/gcode",
           "controllers/g7x", "controllers/lathe_program")
CONTROLLERS = {"panel": "OperatorPanel", "seq": "CutSequencer", "limiter": "AreaLimiter"}

RECORD = r"""
import pickle, sys
from ncfmu.systems import MODELS, get_system
system = get_system("lathe_taper")
objects = {c.name: MODELS[c.model](**c.parameters) for c in system.components}
inputs = {name: type(obj).default_inputs() for name, obj in objects.items()}
outputs = {name: obj.outputs() for name, obj in objects.items()}
wiring = {name: [] for name in objects}
for k in system.connections:
    wiring[k.end_element].append((k.end_connector, outputs[k.start_element], k.start_connector))
order = [(c.name, objects[c.name], inputs[c.name], wiring[c.name]) for c in system.components]
h, n = system.step_size, int(sys.argv[2])
rec = {name: [] for name in objects}
outs = {name: [] for name in objects}
for i in range(n):
    for name, obj, ins, wires in order:
        for port, src, key in wires:
            ins[port] = src[key]
        rec[name].append(dict(ins))
        outs[name].append(dict(obj.step(i * h, h, ins)))
params = {c.name: dict(c.parameters) for c in system.components}
pickle.dump({"params": params, "inputs": rec, "outputs": outs, "h": h}, open(sys.argv[1], "wb"))
"""

REPLAY = r"""
import functools, pickle, sys
root, recording, name, model = sys.argv[1:5]
sys.path.insert(0, root)
import ncfmu.controllers as controllers
d = pickle.load(open(recording, "rb"))
obj = getattr(controllers, model)(**d["params"][name])
ins, outs, h = d["inputs"][name], d["outputs"][name], d["h"]
got = []
def one(acc, i):
    got.append(dict(obj.step(i * h, h, ins[i])))
    return acc
functools.reduce(one, range(len(ins)), None)          # callgrind collects inside reduce only
print("same" if got == outs else "DIFFERENT", sys.modules[type(obj).__module__].__file__)
"""


def compile_copy(into: Path) -> Path:
    shutil.copytree(REPO / "src" / "ncfmu", into / "ncfmu", ignore=shutil.ignore_patterns("*.c", "__pycache__"))
    subprocess.run(["mypyc", *(f"ncfmu/{m}.py" for m in MODULES)], cwd=into, check=True,
                   capture_output=True)
    return into


def instructions(root: Path, recording: Path, name: str, steps: int, tmp: Path) -> tuple[float, str]:
    out = tmp / f"cg.{root.name}.{name}"
    run = subprocess.run(["valgrind", "--tool=callgrind", "--collect-atstart=no",
                          "--toggle-collect=*functools_reduce*", f"--callgrind-out-file={out}", sys.executable,
                          "-c", REPLAY, str(root), str(recording), name, CONTROLLERS[name]],
                         capture_output=True, text=True, check=True)
    total = next(int(line.split()[-1].replace(",", "")) for line in run.stderr.splitlines() if "Collected" in line)
    return total / steps, run.stdout.split()[0]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--compiled", type=Path, help="a copy of src/ncfmu compiled before (the folder holding ncfmu/)")
    ap.add_argument("--steps", type=int, default=3000)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as name:
        tmp = Path(name)
        pure = tmp / "pure"
        shutil.copytree(REPO / "src" / "ncfmu", pure / "ncfmu", ignore=shutil.ignore_patterns("__pycache__"))
        compiled = args.compiled or compile_copy(tmp / "compiled")
        recording = tmp / "inputs.pkl"
        subprocess.run([sys.executable, "-c", RECORD, str(recording), str(args.steps)], check=True, cwd=pure)
        assert pickle.loads(recording.read_bytes())["inputs"]["seq"]
        print(f"lathe_taper, {args.steps} steps of recorded inputs, instructions a step (callgrind)")
        for controller in CONTROLLERS:
            p, _ = instructions(pure, recording, controller, args.steps, tmp)
            c, same = instructions(compiled, recording, controller, args.steps, tmp)
            print(f"  {CONTROLLERS[controller]:<14} pure {p / 1e3:6.1f}k  mypyc {c / 1e3:6.1f}k  "
                  f"x{p / c:4.2f}  outputs {same}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
