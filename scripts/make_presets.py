"""Regenerate the built-in yarn presets (data_formats/presets/*.toml) from the measured parameter tables in
``shared/reference/`` (Zhao et al. 2016 geometry and flyaways, Khungurn et al. 2015 fiber optics).

Usage: python scripts/make_presets.py [REFERENCE_DIR]   (default: ../shared/reference next to the repository)

Conversions (each stated in the preset's provenance):
* ``ply_distance = yarn_radius / 2`` — Wu and Yuksel 2019 §3.1 places ply centres at ½ R_ply from the yarn axis.
* ``ply_semi_axes = [e_long / 2, e_short / 2]`` — the tables' ellipse values read as full axis lengths, consistent
  with the ½ on R_ply; with this reading the fiber packing fraction of every preset lies between 0.05 and 0.6, as
  in real yarns (checked by tests/test_yarn_spec.py), while semi-axes = e would overlap the plies.
* Gaussian draws are mu + 0.5·sigma·N(0, 1) in the source generator, so ``*_std = 0.5 · sigma``.
* ``rho_max = 1`` (R_max = 1 in the source). Fiber radius is not in the tables: typical diameters per fiber family.
* Optics by fiber family from Khungurn et al. 2015: cotton → cotton, polyester → polyester, silk → silk, rayon
  (regenerated-cellulose filament, smooth and lustrous) → silk. Our lobes are energy-normalised (the fiber albedo
  is A_R + A_TT + A_D ≤ 1 per channel; knitrun/shading/fiber_bcsdf.py), Khungurn's were not: R and TT colours are scaled
  by one factor per material so that the brightest channel of R + TT is ``FIBER_ALBEDO`` — hue and the R:TT ratio
  are kept. The D lobe and the lobe shifts are not in the source: D colour = 0 and shifts = 0.
"""

import csv
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from data_formats.yarn_spec import PRESET_DIR, save_spec, spec_from_dict  # noqa: E402

FIBER_RADIUS_CM = {"cotton": 0.0008, "polyester": 0.0009, "rayon": 0.0007, "silk": 0.0006}
OPTICS_FAMILY = {"cotton": "cotton", "polyester": "polyester", "rayon": "silk", "silk": "silk"}
HAIR_CURVATURE_ALPHA = 2.0  # Huang et al. 2025 eq. 13; the paper shows α > 1 for realistic side views
HAIR_DIRECTION_NOISE = 0.15  # rad per unit t; Huang et al. 2025 §4.4 adds noise without a value
FIBER_ALBEDO = 0.95  # brightest channel of A_R + A_TT after rescaling Khungurn's colours


def read_csv(path):
    with open(path, newline="") as fh:
        rows = [line for line in fh if not line.startswith("#")]
    return {r[next(iter(r))]: r for r in csv.DictReader(rows)}


def family(name):
    return name.rstrip("0123456789")


def preset(name, y, f, optics_rows):
    fam = family(name)
    o = optics_rows[OPTICS_FAMILY[fam]]
    num = lambda d, k: float(d[k])  # noqa: E731
    r_col = [num(o, "R_r"), num(o, "R_g"), num(o, "R_b")]
    tt_col = [num(o, "TT_r"), num(o, "TT_g"), num(o, "TT_b")]
    scale = FIBER_ALBEDO / max(r + t for r, t in zip(r_col, tt_col))
    data = {
        "name": name,
        "units": "cm",
        "description": f"{fam} yarn '{name}' measured by micro-CT (Zhao et al. 2016)",
        "provenance": {
            "geometry": "Zhao, Luan & Bala 2016, 'Fitting procedural yarn models for realistic cloth rendering', "
                        "ACM TOG 35(4), as in shared/reference/yarn_params_zhao2016.csv; ply_distance = "
                        "yarn_radius/2 (Wu and Yuksel 2019 §3.1), ply_semi_axes = [e_long/2, e_short/2] (full axes "
                        "read as lengths), rho_max = 1",
            "flyaways": "Zhao et al. 2016 via shared/reference/flyaway_params_zhao2016.csv; std = 0.5*sigma; "
                        f"hair_curvature_alpha = {HAIR_CURVATURE_ALPHA} and hair_direction_noise = "
                        f"{HAIR_DIRECTION_NOISE} rad are our choices (Huang et al. 2025 eq. 13 gives no values)",
            "optics": f"Khungurn et al. 2015 '{OPTICS_FAMILY[fam]}' via shared/reference/fiber_bcsdf_khungurn2015.csv; "
                      f"R and TT colours scaled by {scale:.4f} so the brightest channel of R+TT is {FIBER_ALBEDO} "
                      "(our lobes are energy-normalised); d_color and lobe shifts not in the source (0)",
            "fiber_radius": f"typical {fam} fiber diameter {2e4 * FIBER_RADIUS_CM[fam]:.0f} um (textile handbooks); "
                            "not measured by Zhao et al.",
        },
        "geometry": {
            "plies": int(y["K"]),
            "fibers_per_ply": int(y["m"]),
            "ply_pitch": num(y, "alpha_yarn"),
            "fiber_pitch": num(y, "alpha_fiber"),
            "ply_clockwise": y["cw_yarn"] == "1",
            "fiber_clockwise": y["cw_fiber"] == "1",
            "ply_distance": num(y, "yarn_radius") / 2,
            "ply_semi_axes": [num(y, "e_long") / 2, num(y, "e_short") / 2],
            "fiber_radius": FIBER_RADIUS_CM[fam],
            "density_eps": num(y, "eps"),
            "density_beta": num(y, "beta"),
            "migration_rho_min": num(y, "rho_min"),
            "migration_rho_max": 1.0,
            "migration_frequency": num(y, "s"),
        },
        "flyaways": {
            "hair_density": num(f, "rho_hair"),
            "hair_z_span_mean": num(f, "ze_mu"), "hair_z_span_std": 0.5 * num(f, "ze_sigma"),
            "hair_start_radius_mean": num(f, "r0_mu"), "hair_start_radius_std": 0.5 * num(f, "r0_sigma"),
            "hair_radial_span_mean": num(f, "re_mu"), "hair_radial_span_std": 0.5 * num(f, "re_sigma"),
            "hair_angular_span_mean": num(f, "pe_mu"), "hair_angular_span_std": 0.5 * num(f, "pe_sigma"),
            "hair_curvature_alpha": HAIR_CURVATURE_ALPHA,
            "hair_direction_noise": HAIR_DIRECTION_NOISE,
            "loop_density": num(f, "rho_loop"),
            "loop_radius_mean": num(f, "r1_mu"), "loop_radius_std": 0.5 * num(f, "r1_sigma"),
        },
        "optics": {
            "r_color": [round(scale * v, 6) for v in r_col],
            "tt_color": [round(scale * v, 6) for v in tt_col],
            "d_color": [0.0, 0.0, 0.0],
            "beta_r_deg": num(o, "beta_R"),
            "beta_tt_deg": num(o, "beta_TT"),
            "gamma_tt_deg": num(o, "gamma_TT"),
            "alpha_r_deg": 0.0,
            "alpha_tt_deg": 0.0,
        },
    }
    return spec_from_dict(data, f"preset {name}")


def main(argv):
    ref = Path(argv[1]) if len(argv) > 1 else ROOT.parent / "shared" / "reference"
    yarns = read_csv(ref / "yarn_params_zhao2016.csv")
    flyaways = read_csv(ref / "flyaway_params_zhao2016.csv")
    optics = read_csv(ref / "fiber_bcsdf_khungurn2015.csv")
    PRESET_DIR.mkdir(exist_ok=True)
    for name, y in yarns.items():
        save_spec(PRESET_DIR / f"{name}.toml", preset(name, y, flyaways[name], optics))
        print(f"wrote {PRESET_DIR / (name + '.toml')}")


if __name__ == "__main__":
    main(sys.argv)
