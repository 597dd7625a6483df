"""Regenerate the shipped example tables in data/tables/ from the MERL Neural-BRDF **proxies**.

Each table is a proxy (a neural fit of a MERL measurement, data/nbrdf/PROVENANCE.md)
evaluated on the in-plane grid of a gonioreflectometer like that of Padrón 2025 §4.5
(theta_i in {0, 15, 30, 45, 60, 75} deg, signed theta_o from -85 to 85 deg every 5 deg,
negative = retro-reflection side) and written in the schema of
:mod:`appearance_jax.fit.tables.csv_table` as a reflectance factor against a 99 % white standard,
R = pi f / 0.99: the quantity the cosmetics measurements of the thesis were recorded in.
No noise is added; values are the proxy's, to 9 significant digits.

    python3 fitting/make_proxy_tables.py
"""

from __future__ import annotations

import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FABRICS = ("red-fabric", "white-fabric", "blue-fabric")
# Glossy examples for the fit report (docs/report.md): a metal and a plastic whose mirror peak is
# 4-5 decades above their diffuse part. MERL's nickel and specular-violet-phenolic have no proxy
# (the Neural-BRDF release covers 78 of the 100 MERL materials); these are their nearest kin.
GLOSSY = ("alum-bronze", "specular-blue-phenolic")


def make(name: str, out_dir: str) -> str:
    from appearance_jax.fit import proxy
    from appearance_jax.fit.tables.csv_table import write_csv

    t = proxy.proxy_table(name, "in_plane")
    rf = t.replace(values=t.values * np.pi / 0.99, quantity="reflectance_factor", white_reference=0.99,
                   source=f"MERL {name}, Neural-BRDF PROXY (Sztrajman et al. 2021), in-plane grid; "
                          "made by fitting/make_proxy_tables.py")
    path = os.path.join(out_dir, f"merl-proxy-{name}-in-plane.csv")
    write_csv(rf, path, in_plane=True)
    return path


def main() -> int:
    out = os.path.join(ROOT, "data", "tables")
    os.makedirs(out, exist_ok=True)
    for name in FABRICS + GLOSSY:
        print("wrote", make(name, out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
