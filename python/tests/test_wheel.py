"""The wheel `scripts/build-wheel.sh` builds (scripts/test.sh builds it, and installs it
for the other tests) installs into a fresh virtual environment and runs there with no
Rust toolchain on the PATH: the `bsdfit` command's help, a fit, and a collection's
diagnosis, through the console script the package installs."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import in_ci

REPO = Path(__file__).resolve().parents[2]


def test_the_abi3_wheel_runs_the_command_line_without_rust(tmp_path):
    wheels = sorted((REPO / "target" / "wheels").glob("bsdfit-*.whl"))
    if not wheels:
        if in_ci():
            pytest.fail("no wheel in target/wheels: scripts/test.sh builds it with scripts/build-wheel.sh")
        pytest.skip("no wheel in target/wheels: build it with scripts/build-wheel.sh")
    wheel = wheels[-1]
    assert "-abi3-" in wheel.name, wheel.name
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = subprocess.run([str(venv / "bin" / "pip"), "install", "--quiet", str(wheel)],
                         capture_output=True, text=True)
    assert pip.returncode == 0, pip.stderr
    # Only the venv and the system's programs: no cargo, rustc or maturin.
    path = os.pathsep.join([str(venv / "bin"), "/usr/bin", "/bin"])
    for tool in ("cargo", "rustc", "maturin"):
        assert shutil.which(tool, path=path) is None, f"{tool} is on the test's PATH"
    env = {"PATH": path, "HOME": str(tmp_path), "LANG": "C.UTF-8"}

    def bsdfit(*args, ok=True):
        out = subprocess.run(["bsdfit", *map(str, args)], capture_output=True, text=True,
                             env=env, cwd=tmp_path)
        if ok:
            assert out.returncode == 0, (args, out.stderr)
        return out

    assert shutil.which("bsdfit", path=path) == str(venv / "bin" / "bsdfit")
    help_text = bsdfit("--help").stdout
    assert "diagnose" in help_text and "sweep" in help_text
    usage = bsdfit("fit", "--model", ok=False)  # a usage error: clap's status and message
    assert usage.returncode == 2 and "a value is required for '--model" in usage.stderr
    data = tmp_path / "data"
    data.mkdir()
    bsdfit("synth", "--model", "on", "--params", "rho=0.5,sigma=0.6", "--geometry", "inplane10",
           "--out", data / "on.csv")
    bsdfit("synth", "--model", "lambert", "--geometry", "inplane10", "--seed", "2",
           "--out", data / "lambert.csv")
    bsdfit("fit", data / "on.csv", "--model", "on", "--backend", "cpu", "--json", tmp_path / "fit.json")
    fit = json.loads((tmp_path / "fit.json").read_text())
    sigma = dict(zip(fit["flat_names"], fit["flat_params"]))["sigma"]
    assert abs(sigma - 0.6) < 0.05, fit["flat_params"]
    bsdfit("diagnose", data, "--model", "lambert", "--out", tmp_path / "diag", "--backend", "cpu",
           "--bootstrap", "0", "--max-steps", "1", "--restarts", "2")
    table = json.loads((tmp_path / "diag" / "diagnoses.json").read_text())
    assert {r["data"]: r["effects"] for r in table} == {"on.csv": ["backscatter"], "lambert.csv": []}
