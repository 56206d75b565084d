"""The error models and selection rules of ``wallcal diagnose`` on the real walls, each with its held-out window
(docs/identifiability.md, "Real walls: held-out validation, plausible values and the error model").

    PYTHONPATH=src python bench/validation_arms.py trh passys0 passys

``trh``: the bundled TRH-1 example; ``passys``: examples/passys/study.toml (data read in place from ../shared);
``passys0``: the same with the face offset set to 0 (the data as measured). For each: the calibration's held-out
RMSE, then one line per setting: what diagnose adopts, its values, its BIC change, and the held-out RMSE of the
temperature targets before and after.
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path

from wallcal.analysis.diagnose import diagnose
from wallcal.calibration import calibrate
from wallcal.study import load_study, parse_study
from wallcal.validation import score_wall

ROOT = Path(__file__).resolve().parents[1]
ARMS = {
    "A criterion, bias against all n (before)": dict(selection="criterion", effective_bias_prior=False),
    "B criterion, bias against n_eff": dict(selection="criterion"),
    "C criterion on hourly means, bias against n_eff": dict(selection="criterion", score_resolution=3600),
    "D held-out + plausible, bias against n_eff (default)": dict(),
    "E held-out + plausible, bias against all n": dict(effective_bias_prior=False),
}


def study_of(which: str):
    if which == "trh":
        return load_study(ROOT / "src" / "wallcal" / "examples" / "trh" / "study.toml")
    path = ROOT / "examples" / "passys" / "study.toml"
    raw = copy.deepcopy(load_study(path).raw)
    if which == "passys0":
        for face in ("exterior", "interior"):
            raw["boundary"][face]["offset"] = 0.0
    return parse_study(raw, base_dir=path.parent, source=str(path)).replace(path=path)


def main(names) -> None:
    for which in names:
        st = study_of(which)
        cal = calibrate(st, progress=False)
        v = score_wall(st, cal.wall_opt).set_index("sensor")["rmse"]
        temps = [t for t in st.calibration.targets if st.sensor(t).quantity == "temperature"]
        print(f"## {which}: calibrate held-out RMSE " + ", ".join(f"{t} {v[t]:.3f}" for t in temps))
        for name, kw in ARMS.items():
            d = diagnose(st, start=cal, progress=False, **kw)
            c = d.candidates
            row = c[c["adopted"]].iloc[0] if d.adopted else None
            base = d.validation_base
            held = {t: (row[f"validation RMSE {t}"] if row is not None else base[t]) for t in temps}
            vals = ", ".join(f"{n} = {d.x[n]:.4g}" for n in d.adopted)
            dbic = row["delta_bic"] if row is not None else 0.0
            print(
                f"{which} | {name} | adopted: {' + '.join(d.adopted) or 'nothing'} ({vals}) | dBIC {dbic:+.1f} | "
                "held-out " + ", ".join(f"{t} {base[t]:.3f} -> {held[t]:.3f}" for t in temps),
                flush=True,
            )


if __name__ == "__main__":
    main(sys.argv[1:] or ["trh", "passys0", "passys"])
