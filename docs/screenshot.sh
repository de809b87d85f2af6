#!/usr/bin/env bash
# Takes docs/images/viewer.png: starts the Isoscope viewer in a virtual X display (Xvfb),
# waits until it has rendered, grabs the screen and closes the app.
#
# Installs nothing itself. On a fresh Debian/Ubuntu machine first run (as root):
#   apt-get install -y xvfb imagemagick xdotool libgl1-mesa-dri libegl1 libegl-mesa0
# The app uses eframe's glow (OpenGL) renderer, which runs on Mesa's llvmpipe software driver.
#
# Usage: docs/screenshot.sh [OUTPUT.png] [-- ISOSCOPE ARGS...]
#   ISOSCOPE_BIN  the binary to run (default: target/debug/isoscope, built if missing;
#                 the dev profile is optimized, see the root Cargo.toml)
#   WAIT_SECONDS  how long to let the app load and render before the shot (default 25)
set -euo pipefail

cd "$(dirname "$0")/.."
out="${1:-docs/images/viewer.png}"
shift || true
[[ "${1:-}" == "--" ]] && shift
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

started_xvfb=""
if ! DISPLAY="$display" xdotool getdisplaygeometry >/dev/null 2>&1; then
    setsid nohup Xvfb "$display" -screen 0 1280x800x24 >/dev/null 2>&1 &
    started_xvfb=$!
    for _ in $(seq 50); do
        DISPLAY="$display" xdotool getdisplaygeometry >/dev/null 2>&1 && break
        sleep 0.2
    done
fi

DISPLAY="$display" "$bin" "$@" >/tmp/isoscope-screenshot.log 2>&1 &
app=$!
cleanup() {
    kill "$app" 2>/dev/null || true
    [[ -n "$started_xvfb" ]] && kill "$started_xvfb" 2>/dev/null || true
}
trap cleanup EXIT

sleep "$wait_s"
if ! kill -0 "$app" 2>/dev/null; then
    echo "the app exited early; its log:" >&2
    cat /tmp/isoscope-screenshot.log >&2
    exit 1
fi
mkdir -p "$(dirname "$out")"
DISPLAY="$display" import -window root "$out"
echo "wrote $out"
