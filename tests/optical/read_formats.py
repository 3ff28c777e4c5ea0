"""An independent reader of the Zemax tabular BSDF and ASTM E1392 files bsdfit writes,
written from the formats' definitions (docs/data-formats.md quotes them) with the Python
standard library only: it shares no code with bsdfit's readers or writers.

    python3 read_formats.py zemax FILE   ->  JSON of the header and every cell
    python3 read_formats.py astm FILE    ->  JSON of the header and every row

Each cell and row comes with its geometry in bsdfit's angles (degrees): (theta_i, phi_i,
theta_o, phi_o), theta_o measured from -n for a transmitted direction.
"""

import json
import math
import sys


def zemax_direction(rotation, aoi, azimuth, radial):
    """A Zemax cell's scattered direction, from the definitions (docs/data-formats.md):
    the radial angle is 0 at the specular direction and grows outwards; the azimuth is 0
    on the side facing the sample normal and turns counter-clockwise; the sample rotation
    is the angle from the sample's +X axis to the normal of the plane of incidence, so the
    source is at azimuth rotation + 90 deg.

    Built by spherical trigonometry on the great circle through the specular direction s
    and the normal: the direction at angular distance r from s, along the bearing a
    measured from the direction towards the normal, counter-clockwise seen from above.
    Returns (theta_i, phi_i, theta_o, phi_o, cos_o), theta_o on the scattered side."""
    phi_i = (rotation + 90.0) % 360.0
    if aoi == 0.0:
        # The specular direction is the normal: "towards the normal" is, by continuity from
        # aoi > 0 (where s lies on the far side, at longitude phi_i + 180), the longitude
        # phi_i, and counter-clockwise from above adds to the longitude.
        c = math.radians(radial)
        return (aoi, phi_i, radial, (phi_i + azimuth) % 360.0 if radial > 0 else 0.0, math.cos(c))
    # The specular direction: polar angle aoi, azimuth phi_i + 180 (colatitude c0).
    c0 = math.radians(aoi)
    lon0 = math.radians(phi_i + 180.0)
    r = math.radians(radial)
    # A navigation bearing is measured from "north" (towards the pole, i.e. the normal)
    # clockwise seen from above the pole, towards increasing longitude; the Zemax azimuth
    # turns counter-clockwise seen from above (the illuminated side), so b = -azimuth.
    b = -math.radians(azimuth)
    # Spherical law of cosines for the colatitude of the point.
    cos_c = math.cos(c0) * math.cos(r) + math.sin(c0) * math.sin(r) * math.cos(b)
    cos_c = max(-1.0, min(1.0, cos_c))
    c = math.acos(cos_c)
    # Longitude difference (east = increasing longitude): atan2 form of the spherical
    # triangle with the pole.
    dlon = math.atan2(math.sin(b) * math.sin(r) * math.sin(c0),
                      math.cos(r) - math.cos(c0) * cos_c)
    lon = lon0 + dlon
    if c < 1e-12:
        lon = 0.0
    return (aoi, phi_i, math.degrees(c), math.degrees(lon) % 360.0, cos_c)


def read_zemax(path):
    lines = []
    with open(path, encoding="utf-8") as f:
        for raw in f:
            t = raw.strip()
            if not t or t.startswith("#"):
                continue
            lines.append(t.split())
    head = {}
    i = 0
    lists = ("SampleRotation", "AngleOfIncidence", "ScatterAzimuth", "ScatterRadial")
    while lines[i][0] not in ("Monochrome", "TristimulusX", "DataBegin"):
        key = lines[i][0]
        if key in lists:
            n = int(lines[i][1])
            values = [float(x) for x in lines[i][2:]]
            while len(values) < n:
                i += 1
                values += [float(x) for x in lines[i]]
            head[key] = values
        else:
            head[key] = lines[i][1]
        i += 1
    rot, aoi, az, rad = (head[k] for k in lists)
    tables = []
    section = None
    while i < len(lines):
        word = lines[i][0]
        if word in ("Monochrome", "TristimulusX", "TristimulusY", "TristimulusZ"):
            section = word
            i += 1
        elif word in ("DataBegin", "DataEnd"):
            i += 1
        elif word == "TIS":
            block = sum(1 for t in tables if t["section"] == section)
            r0 = rot[block // len(aoi)]
            a0 = aoi[block % len(aoi)]
            rows = [[float(x) for x in lines[i + 1 + j]] for j in range(len(az))]
            assert all(len(row) == len(rad) for row in rows), "a row of the wrong length"
            cells = []
            for j, a in enumerate(az):
                for k, r in enumerate(rad):
                    g = zemax_direction(r0, a0, a, r)
                    cells.append({"azimuth": a, "radial": r, "value": rows[j][k],
                                  "geometry": g[:4], "above_horizon": g[4] > 1e-9})
            tables.append({"section": section, "rotation": r0, "aoi": a0,
                           "tis": float(lines[i][1]), "cells": cells})
            i += 1 + len(az)
        else:
            raise ValueError("unexpected line: " + " ".join(lines[i]))
    return {"symmetry": head["Symmetry"], "spectral": head["SpectralContent"],
            "kind": head["ScatterType"], "rotations": rot, "aoi": aoi,
            "azimuths": az, "radials": rad, "tables": tables}


def read_astm(path):
    keys = {}
    rows = []
    names = None
    with open(path, encoding="utf-8") as f:
        for raw in f:
            t = raw.strip()
            if not t:
                continue
            if names is None:
                key, _, value = t.partition(" ")
                if key == "VARS":
                    names = [n.strip() for n in value.split(",")]
                else:
                    keys[key] = value.strip()
                continue
            rows.append([float(x) for x in t.split(",")])
    unit = keys.get("ANGLE_UNITS", "RAD").upper()
    to_deg = 1.0 if unit.startswith("DEG") else 180.0 / math.pi
    out = []
    for r in rows:
        assert len(r) == len(names), "a row of the wrong length"
        ti, pi_, ts, ps = (r[names.index(n)] * to_deg for n in ("theta_i", "phi_i", "theta_s", "phi_s"))
        transmitted = ts > 90.0
        to = 180.0 - ts if transmitted else ts
        values = {n: r[k] for k, n in enumerate(names) if k >= 4}
        out.append({"geometry": [ti, pi_, to, ps], "transmitted": transmitted, "values": values})
    return {"keys": keys, "vars": names, "rows": out}


if __name__ == "__main__":
    kind, path = sys.argv[1], sys.argv[2]
    data = read_zemax(path) if kind == "zemax" else read_astm(path)
    json.dump(data, sys.stdout)
