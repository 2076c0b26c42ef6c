#!/usr/bin/python3
"""Slices a small part with real printer profiles into OUT_DIR, for the G-code reader's test.

PrusaSlicer (Debian's prusa-slicer): one printer of each vendor bundle it ships per G-code flavour
and E mode, plus printers whose start and end G-code are known to be unusual (Prusa's firmware
checks, a multi-material printer, Klipper macros). A vendor bundle's printer is a chain of
`inherits`; it is flattened into one config file here, since the slicer's command line loads
config files, not bundle presets. The print and filament settings are the slicer's defaults.

Slic3r 1.3 (Debian's slic3r): every G-code flavour it writes, volumetric E, and 2.85 mm filament.

Each file is OUT_DIR/NAME.gcode; OUT_DIR/index.tsv lists its name, the slicer's printer and options,
and what the reader must refuse it for (empty: it must load).
"""
import configparser
import glob
import os
import subprocess
import sys

PROFILES = "/usr/share/PrusaSlicer/profiles"
PART = "/usr/share/PrusaSlicer/shapes/box.stl"  # a 30 mm cube, scaled to 9 mm below: a few layers
# (vendor, printer, slicer options, what the reader must refuse it for or ""): what the one printer
# per flavour would miss.
EXTRA_PRINTERS = [
    ("PrusaResearch", "Original Prusa i3 MK3S & MK3S+", [], ""),        # M862.3 P "MK3S", M115 U…, G80
    ("PrusaResearch", "Original Prusa i3 MK3S & MK3S+ MMU2S", [], ""),  # tool changes, a wipe tower
    ("PrusaResearch", "Original Prusa i3 MK3S & MK3S+", ["--use-volumetric-e"], ""),
    ("PrusaResearch", "Original Prusa i3 MK3S & MK3S+", ["--filament-diameter", "2.85"], ""),
    # mach3 puts the slicer's extrusion on A, but the MK3S's start G-code (its purge line) still
    # extrudes on E: a file no machine prints as meant.
    ("PrusaResearch", "Original Prusa i3 MK3S & MK3S+", ["--gcode-flavor", "mach3"],
     "G1 moves E, but the file's slicer settings put the extrusion on A"),
    ("Voron", "Voron_v2_250_afterburner 0.4 nozzle", [], ""),           # Klipper's print_start macro
    ("Creality", "Creality Ender-3 V2 (0.4 mm nozzle)", [], ""),
]
SLIC3R_FLAVOURS = ["reprap", "repetier", "teacup", "makerware", "sailfish", "mach3", "machinekit", "smoothie"]


def read_bundle(path):
    bundle = configparser.RawConfigParser(strict=False, interpolation=None, comment_prefixes=("#",),
                                          inline_comment_prefixes=None, delimiters=("=",))
    bundle.optionxform = str  # keys are case-sensitive
    bundle.read(path)
    return bundle


def printer_config(bundle, name):
    """A printer preset with its `inherits` chain applied, parents first."""
    section = bundle["printer:" + name]
    config = {}
    for parent in (p.strip() for p in section.get("inherits", "").split(";")):
        if parent:
            config.update(printer_config(bundle, parent))
    config.update({key: value for key, value in section.items() if key != "inherits"})
    return config


def bed_centre(config):
    points = [tuple(float(v) for v in point.split("x")) for point in config.get("bed_shape", "0x0,200x200").split(",")]
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    return (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2


def slice_with(command, output, log):
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0 or not os.path.exists(output):
        sys.exit(f"slicing failed ({' '.join(command)}):\n{result.stdout}\n{result.stderr}")
    log.write(result.stdout)


def main():
    out_dir = sys.argv[1]
    os.makedirs(out_dir, exist_ok=True)
    index, log = [], open(os.path.join(out_dir, "slicer.log"), "w")

    chosen, seen = list(EXTRA_PRINTERS), set()
    for path in sorted(glob.glob(os.path.join(PROFILES, "*.ini"))):
        vendor = os.path.basename(path)[:-4]
        bundle = read_bundle(path)
        for section in bundle.sections():
            if not section.startswith("printer:") or section.startswith("printer:*"):
                continue
            config = printer_config(bundle, section[len("printer:"):])
            if config.get("printer_technology", "FFF") != "FFF":
                continue  # resin printers write no G-code
            kind = (vendor, config.get("gcode_flavor"), config.get("use_volumetric_e", "0"))
            if kind not in seen:
                seen.add(kind)
                chosen.append((vendor, section[len("printer:"):], [], ""))

    for number, (vendor, printer, options, refusal) in enumerate(chosen):
        config = printer_config(read_bundle(os.path.join(PROFILES, vendor + ".ini")), printer)
        for key in ("compatible_printers", "compatible_printers_condition", "renamed_from", "host_type", "thumbnails"):
            config.pop(key, None)
        name = f"prusaslicer_{number:02d}"
        config_file = os.path.join(out_dir, name + ".ini")
        with open(config_file, "w") as stream:
            stream.writelines(f"{key} = {value}\n" for key, value in config.items())
        x, y = bed_centre(config)
        # Layers the nozzle can lay (the default first layer is thicker than a 0.25 mm nozzle).
        layer = float(config.get("nozzle_diameter", "0.4").split(",")[0]) / 2
        layers = ["--layer-height", f"{layer:g}", "--first-layer-height", f"{layer:g}"]
        output = os.path.join(out_dir, name + ".gcode")
        slice_with(["prusa-slicer", "--export-gcode", "--load", config_file, *layers, *options, "--scale", "0.3", "--center", f"{x:g},{y:g}",
                    "--output", output, PART], output, log)
        index.append((name, f"{vendor}: {printer} ({config.get('gcode_flavor')}) {' '.join(options)}".strip(), refusal))

    variants = [(flavour, ["--gcode-flavor", flavour]) for flavour in SLIC3R_FLAVOURS]
    variants += [("volumetric", ["--use-volumetric-e"]), ("filament_2.85", ["--filament-diameter", "2.85"]),
                 ("relative_e", ["--use-relative-e-distances"])]
    for label, options in variants:
        name = f"slic3r_{label}"
        output = os.path.join(out_dir, name + ".gcode")
        slice_with(["slic3r", "--no-gui", *options, "--scale", "0.3", "--print-center", "100,100", "--output", output, PART],
                   output, log)
        index.append((name, f"Slic3r 1.3: {label}", ""))

    with open(os.path.join(out_dir, "index.tsv"), "w") as stream:
        stream.writelines("\t".join(row) + "\n" for row in index)
    print(f"{len(index)} files sliced into {out_dir}")


if __name__ == "__main__":
    main()
