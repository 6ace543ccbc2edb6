#!/bin/sh
# Renders a dhct report.html in headless Chromium and saves a full-page screenshot, to look
# at the report the way a reader's browser shows it (no network is used).
#   scripts/report_screenshot.sh OUTDIR/report.html [shot.png] [height-px]
# Needs Debian's chromium (apt install chromium).
set -eu
report=$(realpath "$1")
shot=${2:-report.png}
height=${3:-6000}
profile=$(mktemp -d)
trap 'rm -rf "$profile"' EXIT
chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync \
    --hide-scrollbars --user-data-dir="$profile" --window-size=1280,"$height" \
    --screenshot="$shot" "file://$report" 2>/dev/null
echo "wrote $shot"
