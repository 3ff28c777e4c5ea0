"""Zemax tabular BSDF and ASTM E1392 files through Dataset.read (the command line's
readers, recognised by content): the worked examples of docs/data-formats.md, written
here from the format definitions."""

import math

import numpy as np
import pytest

import bsdfit

ZEMAX = """# example: a diffuser measured at 20 degrees
Source  Measured
Symmetry  PlaneSymmetrical
SpectralContent  Monochrome
ScatterType  BTDF
SampleRotation  1
0
AngleOfIncidence  1
20
ScatterAzimuth  3
0\t90\t180
ScatterRadial  3
0\t10\t80

Monochrome
DataBegin
TIS 0.62
1.20E+00\t9.00E-01\t0.00E+00
1.20E+00\t8.50E-01\t1.00E-02
1.20E+00\t8.00E-01\t0.00E+00
DataEnd
"""

ASTM = """SOURCE Test lab
SAMPLE_NAME "blue paint"
NUM_POINTS 2
VARS theta_i,phi_i,theta_s,phi_s,400nm,410nm
0.34906585,0,0.34906585,3.14159265,0.0421,0.0433
0.34906585,0,0.52359878,2.35619449,0.0398,0.0405
"""


def test_a_zemax_btdf_reads_at_its_documented_geometry(tmp_path):
    path = tmp_path / "diffuser.bsdf"
    path.write_text(ZEMAX)
    # No uncertainties in the format: refused at the first data line, line and column named.
    with pytest.raises(ValueError, match=r"diffuser\.bsdf:15:1: .*--assume-uncertainty"):
        bsdfit.Dataset.read(path)
    data = bsdfit.Dataset.read(path, assume_uncertainty=(0.02, 1e-4))
    assert data.kind == "btdf" and data.channels == [550.0]
    order = np.argsort(data.theta_o)
    # The cells of the worked example: radial 0 once (the direct transmission, θt = 20°),
    # then (0, 10), (90, 10), (180, 10), (90, 80); the masked and beyond-horizon cells
    # are skipped. φi = sample rotation + 90°.
    assert np.allclose(data.theta_o[order], [10.0, 20.0, 22.268744495, 30.0, 80.608714198], atol=1e-6)
    assert np.allclose(data.value[order], [0.9, 1.2, 0.85, 0.8, 0.01])
    assert np.all(data.phi_i == 90.0) and np.all(data.theta_i == 20.0)


def test_an_astm_file_in_radians_reads_with_its_channels(tmp_path):
    path = tmp_path / "paint.astm"
    path.write_text(ASTM)
    data = bsdfit.Dataset.read(path, assume_uncertainty=(0.02, 1e-4))
    assert data.kind == "brdf" and data.material == "blue paint"
    assert data.channels == [400.0, 410.0] and len(data) == 4
    assert np.allclose(np.unique(np.round(data.theta_o, 6)), [20.0, 30.0])
    assert math.isclose(data.value[data.wavelength_nm == 410.0][0], 0.0433)
    path.write_text(ASTM.replace("NUM_POINTS 2", "NUM_POINTS 3"))
    with pytest.raises(ValueError, match=r"paint\.astm:3:12: NUM_POINTS 3"):
        bsdfit.Dataset.read(path, assume_uncertainty=(0.02, 1e-4))
