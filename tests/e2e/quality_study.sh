#!/usr/bin/env bash
# scenes/quality_study.sdf: one wall in three materials, and the quality report says which held its
# shape, from the particles alone: the Newtonian paste falls short at its first layer, the soft mortar
# (60 Pa) a few layers up and later, the stiff one (800 Pa) stands at its designed 30 mm with beads of
# the designed width. The run's summary.json, quality.json (read by Python's json) and m3dp quality's
# remake agree; quality.png (read by PIL) is drawn.
set -euo pipefail
m3dp=$1 scenes=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
"$m3dp" run "$scenes/quality_study.sdf" -o "$work/run" --quiet > "$work/run.out"
grep "quality " "$work/run.out"
cp "$work/run/quality.json" "$work/in_run_quality.json"
"$m3dp" quality "$work/run" > "$work/quality.out"
grep "height of" "$work/quality.out"
/usr/bin/python3 - "$work/run" "$work/in_run_quality.json" <<'PY'
import json, pathlib, sys
from PIL import Image
folder = pathlib.Path(sys.argv[1])
summary = json.loads((folder / "summary.json").read_text())["quality"]
in_run = json.loads(pathlib.Path(sys.argv[2]).read_text())
offline = json.loads((folder / "quality.json").read_text())
verdicts = {head["name"]: head for head in summary["heads"]}
assert list(verdicts) == ["paste", "soft_mortar", "stiff_mortar"], list(verdicts)
paste, soft, stiff = verdicts["paste"], verdicts["soft_mortar"], verdicts["stiff_mortar"]
assert not paste["stood"] and paste["shortfall"]["layer"] == 0, paste
assert not soft["stood"] and soft["shortfall"]["layer"] >= 1, soft
assert soft["shortfall"]["time_s"] > paste["shortfall"]["time_s"] + 1, (soft, paste)
assert stiff["stood"] and stiff["shortfall"] is None, stiff
assert summary["stood"] is False  # the print as a whole did not
for report in (in_run, offline):
    heads = {head["name"]: head for head in report["heads"]}
    for name, verdict in verdicts.items():
        height = heads[name]["height"]
        assert height["stood"] == verdict["stood"], (name, height["shortfall"], verdict)
        if height["shortfall"]:
            assert height["shortfall"]["layer"] == verdict["shortfall"]["layer"], (name, height["shortfall"])
            assert abs(height["shortfall"]["time_s"] - verdict["shortfall"]["time_s"]) < 1e-6
    # The stiff wall: its height as designed (30 mm, within 10 %), each layer's bead as wide as
    # designed within 8 %; the paste's first layer spread to well over its designed width.
    last = heads["stiff_mortar"]["height"]["history"][-1]
    assert abs(last[3] - 0.030) < 0.003 and abs(last[2] - 0.030) < 1e-9, last
    for layer in heads["stiff_mortar"]["layers"]:
        assert layer["stations_empty"] == 0 and abs(layer["width_m"] / layer["design_width_m"] - 1) < 0.08, layer
    first = heads["paste"]["layers"][0]
    assert first["width_m"] > 1.5 * first["design_width_m"], first
with Image.open(folder / "quality.png") as image:
    assert image.size[0] > 1200 and image.size[1] > 700, image.size
stiff_widths = [round(1e3 * layer["width_m"], 1) for layer in {h["name"]: h for h in offline["heads"]}["stiff_mortar"]["layers"]]
print(f"paste fell short at layer 0 ({paste['shortfall']['time_s']:.2f} s), soft mortar at layer {soft['shortfall']['layer']} "
      f"({soft['shortfall']['time_s']:.2f} s), stiff mortar stood; its beads {stiff_widths} mm wide (design "
      f"{1e3 * offline['heads'][2]['layers'][0]['design_width_m']:.1f})")
PY
echo "PASS"
