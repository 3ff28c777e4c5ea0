"""Shared by the RGL tests: a fit exported with `bsdfit export --format rgl`."""

import subprocess

from test_bsdfit import cli_command


def export(fit, tmp_path, name, *extra):
    """Write `fit` as a JSON report, export it as `<name>.bsdf`, return the file's path."""
    src = tmp_path / f"{name}.json"
    fit.to_json(src)
    out = tmp_path / f"{name}.bsdf"
    done = subprocess.run(cli_command() + ["export", str(src), "--format", "rgl", "--out", str(out), *extra],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return out
