"""The README's first command, as a new user runs it: a copy of the checkout, a new venv, an empty compile cache
(pip's own wheel cache reused: it holds the same pinned files pip would download). The main job gets compiled
controllers with no extra, and says so while it compiles (issue 47)."""

import os
import re
import subprocess
import sys
import sysconfig
import time
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def readme_commands() -> list[str]:
    """The one-line commands of the README's first two ```bash blocks (what .ci/run runs)."""
    commands, inside, blocks = [], False, 0
    for line in (ROOT / "README.md").read_text().splitlines():
        if line == "```bash":
            inside = True
        elif line == "```":
            blocks += inside
            inside = False
        elif inside and blocks < 2 and line.strip():
            commands.append(line)
    return commands


@pytest.mark.slow
def test_readme_first_command_on_a_bare_venv_compiles_the_controllers(tmp_path):
    from ncfmu.fmi.builder import COMPILED, COMPILING
    first = readme_commands()[0]
    assert first == "pip install -c .ci/constraints.txt -e . && ncfmu run"
    checkout, venv, cache = tmp_path / "checkout", tmp_path / "venv", tmp_path / "cache"
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"], cwd=ROOT,
                           capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, files):
        if (ROOT / name).is_file():
            (checkout / name).parent.mkdir(parents=True, exist_ok=True)
            (checkout / name).write_bytes((ROOT / name).read_bytes())
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NCFMU_", "PYTHON", "VIRTUAL_ENV"))}
    env.update(PATH=f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}", VIRTUAL_ENV=str(venv),
               NCFMU_CACHE=str(cache))
    started = time.monotonic()
    done = subprocess.run(["bash", "-euo", "pipefail", "-c", first], cwd=checkout, env=env, capture_output=True,
                          text=True, timeout=1800)
    wall = time.monotonic() - started
    print(f"README's first command: {wall:.0f} s wall")
    assert done.returncode == 0, done.stderr[-3000:]
    assert f"{COMPILING}: generating C ..." in done.stderr and re.search(rf"{re.escape(COMPILING)}: done in \d+ s",
                                                                         done.stderr)
    assert "not compiled" not in done.stderr
    assert "\nsystem lathe_roughing: simulated" in done.stdout        # after pip's own lines
    ext = sysconfig.get_config_var("EXT_SUFFIX")
    with zipfile.ZipFile(checkout / "fmus" / "CutSequencer.fmu") as fmu:
        shipped = {n.split("/", 2)[2] for n in fmu.namelist() if n.startswith("resources/ncfmu_") and n.endswith(ext)}
    assert {f"{m[:-3]}{ext}" for m in COMPILED} <= shipped
    assert (checkout / "fmus" / "ncfmu-build-kind").read_text() == "compiled\n"
