#!/usr/bin/env bash
# End to end: the demo's wrist and overview cameras, read back by tools we did not write. Debian's
# python3 with PIL and numpy checks every image, the overview seeing the arm and the wrist seeing
# the fresh bead at its layer's height (tests/e2e/cameras_read.py); ImageMagick's identify reports
# the sizes and bit depths; m3dp render draws the same frame identically on 1 and 2 threads.
set -euo pipefail
m3dp=$1 scene=$2 out=$3
python=/usr/bin/python3  # Debian's, which has python3-pil and python3-numpy (not a pyenv one)
here=$(dirname "$0")
rm -rf "$out"
"$m3dp" run "$scene" -o "$out/run" --until 14 --quiet > /dev/null
"$python" "$here/cameras_read.py" "$out/run"

expect_identify() {  # file, expected "WxH depth-bit colourspace" words
  local got
  got=$(identify -format '%m %wx%h %z-bit %[colorspace]' "$1")
  [ "$got" = "$2" ] || { echo "FAIL: identify $1: '$got', expected '$2'"; exit 1; }
}
expect_identify "$out/run/cameras/wrist/rgb_000010.png" "PNG 320x240 8-bit sRGB"
expect_identify "$out/run/cameras/wrist/depth_000010.png" "PNG 320x240 16-bit Gray"
expect_identify "$out/run/cameras/wrist/segmentation_000010.png" "PNG 320x240 16-bit Gray"
expect_identify "$out/run/cameras/overview/rgb_000005.png" "PNG 640x480 8-bit sRGB"

# The same frame on one and two threads: the same bytes.
"$m3dp" render "$out/run" --camera overview --time 12 --threads 1 -o "$out/overview_1.png" > /dev/null
"$m3dp" render "$out/run" --camera overview --time 12 --threads 2 -o "$out/overview_2.png" > /dev/null
cmp "$out/overview_1.png" "$out/overview_2.png" || { echo "FAIL: the overview differs on 1 and 2 threads"; exit 1; }
"$m3dp" render "$out/run" --eye 1.3 -0.9 0.6 --target 0.62 0 0.1 --width 400 --height 300 --threads 1 -o "$out/eye_1.png" > /dev/null
"$m3dp" render "$out/run" --eye 1.3 -0.9 0.6 --target 0.62 0 0.1 --width 400 --height 300 --threads 2 -o "$out/eye_2.png" > /dev/null
cmp "$out/eye_1.png" "$out/eye_2.png" || { echo "FAIL: the free view differs on 1 and 2 threads"; exit 1; }
expect_identify "$out/eye_1.png" "PNG 400x300 8-bit sRGB"
# Neither a camera nor an eye point: a view that frames the arm and the print (read by PIL: the
# picture's subject spans most of its height, the arm's blue links whole in it).
"$m3dp" render "$out/run" --time 12 -o "$out/framed.png" > "$out/framed.txt"
grep -q "from a view framing the robots and the print (--eye " "$out/framed.txt" || { echo "FAIL: $(cat "$out/framed.txt")"; exit 1; }
/usr/bin/python3 - "$out/framed.png" <<'PY'
import sys
import numpy as np
from PIL import Image
with Image.open(sys.argv[1]) as image:
    assert image.size == (1280, 960), image.size
    pixels = np.asarray(image.convert("RGB")).astype(int)
background = pixels[0, 0]
subject = np.abs(pixels - background).sum(axis=2) > 30
rows, columns = np.nonzero(subject)
height, width = (rows.max() - rows.min()) / pixels.shape[0], (columns.max() - columns.min()) / pixels.shape[1]
blue = ((pixels[:, :, 2] > pixels[:, :, 0] + 20) & subject).mean()
arm_rows, arm_columns = np.nonzero((pixels[:, :, 2] > pixels[:, :, 0] + 20) & subject)  # the arm whole, not cut by an edge
assert max(height, width) > 0.6, (height, width)
assert arm_rows.min() > 0 and arm_columns.min() > 0 and arm_rows.max() < 959 and arm_columns.max() < 1279, (arm_rows.min(), arm_rows.max())
assert 0.05 < subject.mean() < 0.8 and blue > 0.02, (subject.mean(), blue)
print(f"framed: the subject spans {height:.0%} of the height and {width:.0%} of the width; {blue:.1%} of the pixels the arm's blue")
PY
# An unknown camera is an error that lists the scene's.
if "$m3dp" render "$out/run" --camera nosuch -o "$out/x.png" 2> "$out/error.txt"; then echo "FAIL: an unknown camera rendered"; exit 1; fi
grep -q "has no camera 'nosuch'; its cameras: overview, wrist" "$out/error.txt" || { echo "FAIL: $(cat "$out/error.txt")"; exit 1; }
echo "PASS"
