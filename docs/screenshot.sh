#!/usr/bin/env bash
# Takes the viewer screenshots in docs/images/: starts the Isoscope viewer in a virtual X
# display (Xvfb), waits until it has rendered, grabs the screen and closes the app.
#
# Installs nothing itself. On a fresh Debian/Ubuntu machine first run (as root):
#   apt-get install -y xvfb imagemagick xdotool libgl1-mesa-dri libegl1 libegl-mesa0
# The app uses eframe's glow (OpenGL) renderer, which runs on Mesa's llvmpipe software driver.
#
# Usage: docs/screenshot.sh                 both shots below
#        docs/screenshot.sh OUTPUT.png [-- ISOSCOPE ARGS...]   one shot of `isoscope ARGS`
#   docs/images/viewer.png           the embedded Marschner–Lobb sample (no arguments)
#   docs/images/screenshot-tet.png   a generated tet mesh (`isoscope generate tet-ball`)
#                                    restored from a session: point array "gaussians", an
#                                    opaque isosurface inside a transparent one
#   docs/images/picking.png          the embedded sample clicked in the middle of the view:
#                                    the pick panel and the marker
#   docs/images/color-by.png         the tet mesh's "gaussians" isosurface coloured by its
#                                    "distance" array (coolwarm) with the scalar bar
#   docs/images/dicom-ct.png         a CT-like DICOM series written by pydicom
#                                    (data-samples/scripts/make_dicom_ct.py; needs PYTHON
#                                    with numpy and pydicom, skipped without), skin and bone
#                                    in HU, seen from the patient's front right, with the
#                                    orientation marker
#   PYTHON        the Python for the DICOM shot (default python3)
#   ISOSCOPE_BIN  the binary to run (default: target/debug/isoscope, built if missing;
#                 the dev profile is optimized, see the root Cargo.toml)
#   WAIT_SECONDS  how long to let the app load and render before the shot (default 25)
#   CLICK_AT      "X Y": screen position to click after the wait (then 8 s more), for
#                 picking
set -euo pipefail

cd "$(dirname "$0")/.."
bin="${ISOSCOPE_BIN:-target/debug/isoscope}"
wait_s="${WAIT_SECONDS:-25}"
display="${SCREENSHOT_DISPLAY:-:99}"

for tool in Xvfb import xdotool; do
    command -v "$tool" >/dev/null || { echo "missing $tool: see the apt-get line at the top" >&2; exit 1; }
done
[[ -x "$bin" ]] || cargo build -p isoscope

# A fresh XDG runtime dir silences winit's warning; a private config dir keeps the user's
# saved window layout out of the picture.
export XDG_RUNTIME_DIR="$(mktemp -d)"
export XDG_CONFIG_HOME="$(mktemp -d)"
export XDG_DATA_HOME="$XDG_CONFIG_HOME"
work="$(mktemp -d)"

started_xvfb=""
app=""
cleanup() {
    [[ -n "$app" ]] && kill "$app" 2>/dev/null || true
    [[ -n "$started_xvfb" ]] && kill "$started_xvfb" 2>/dev/null || true
    rm -rf "$work"
}
trap cleanup EXIT
if ! DISPLAY="$display" xdotool getdisplaygeometry >/dev/null 2>&1; then
    setsid nohup Xvfb "$display" -screen 0 1280x800x24 >/dev/null 2>&1 &
    started_xvfb=$!
    for _ in $(seq 50); do
        DISPLAY="$display" xdotool getdisplaygeometry >/dev/null 2>&1 && break
        sleep 0.2
    done
fi

# shot OUTPUT.png [ISOSCOPE ARGS...]: one run of the viewer, one picture of the screen.
shot() {
    local out="$1"
    shift
    DISPLAY="$display" "$bin" "$@" >"$work/app.log" 2>&1 &
    app=$!
    sleep "$wait_s"
    if ! kill -0 "$app" 2>/dev/null; then
        echo "the app exited early; its log:" >&2
        cat "$work/app.log" >&2
        exit 1
    fi
    if [[ -n "${CLICK_AT:-}" ]]; then
        # shellcheck disable=SC2086
        DISPLAY="$display" xdotool mousemove $CLICK_AT click 1
        sleep 8
    fi
    mkdir -p "$(dirname "$out")"
    DISPLAY="$display" import -window root "$out"
    kill "$app" 2>/dev/null || true
    wait "$app" 2>/dev/null || true
    app=""
    echo "wrote $out"
}

if [[ $# -gt 0 ]]; then
    out="$1"
    shift
    [[ "${1:-}" == "--" ]] && shift
    shot "$out" "$@"
    exit 0
fi

shot docs/images/viewer.png

# A tet mesh with two isosurfaces of its "gaussians" array, the outer one transparent: the
# session file (File → Save session… writes the same format) sets the array, surfaces and
# camera; opening a session file restores it.
"$bin" generate tet-ball --tets 300000 -o "$work/ball.vtu" >/dev/null
cat >"$work/ball-session.json" <<JSON
{
  "version": 1,
  "files": ["$work/ball.vtu"],
  "field": "gaussians",
  "camera": {"azimuth_deg": 60.0, "elevation_deg": 25.0, "zoom": 0.62},
  "surfaces": [
    {"isovalue": 0.7, "color": [0.90, 0.75, 0.55], "opacity": 1.0, "visible": true},
    {"isovalue": 0.3, "color": [0.35, 0.60, 0.95], "opacity": 0.4, "visible": true}
  ],
  "render": {"max_layers": 8}
}
JSON
shot docs/images/screenshot-tet.png "$work/ball-session.json"
# Colour by field: the "gaussians" isosurface of the same mesh coloured by its "distance"
# array through coolwarm over 0.3–0.9, with the scalar bar over the view.
cat >"$work/color-session.json" <<JSON
{
  "version": 1,
  "files": ["$work/ball.vtu"],
  "field": "gaussians",
  "camera": {"azimuth_deg": 40.0, "elevation_deg": 20.0, "zoom": 0.62},
  "surfaces": [
    {"isovalue": 0.25, "color": [0.90, 0.75, 0.55], "opacity": 1.0, "visible": true,
     "color_by": {"field": {"field": "distance"}, "colormap": "coolwarm", "range": [0.3, 0.9]}}
  ]
}
JSON
shot docs/images/color-by.png "$work/color-session.json"
# Picking: the embedded sample clicked in the middle of its view (the viewport's centre on
# the 1280×800 screen).
CLICK_AT="${PICK_AT:-760 420}" shot docs/images/picking.png
# A DICOM CT: the series is written by pydicom, opened as a folder (LPS world, HU values);
# the session sets a front-right view (LPS: anterior is −y, right is −x) and two surfaces.
python="${PYTHON:-python3}"
if "$python" -c "import numpy, pydicom" 2>/dev/null; then
    "$python" data-samples/scripts/make_dicom_ct.py "$work/ct" --size 256 --slices 160
    cat >"$work/ct-session.json" <<JSON
{
  "version": 1,
  "files": ["$work/ct"],
  "camera": {"azimuth_deg": 235.0, "elevation_deg": 15.0, "zoom": 0.8},
  "surfaces": [
    {"isovalue": 500.0, "color": [0.92, 0.88, 0.78], "opacity": 1.0, "visible": true},
    {"isovalue": -300.0, "color": [0.85, 0.55, 0.45], "opacity": 0.35, "visible": true}
  ],
  "clip_boxes": [
    {"enabled": true, "min": [0.0, 0.0, 0.55], "max": [0.5, 0.5, 1.0], "keep": "Outside"}
  ],
  "render": {"max_layers": 6}
}
JSON
    shot docs/images/dicom-ct.png "$work/ct-session.json"
else
    echo "skipped docs/images/dicom-ct.png: $python has no numpy/pydicom" >&2
fi
