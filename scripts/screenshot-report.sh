#!/usr/bin/env bash
# Screenshot a sweep's report.html in headless Chromium (Debian package `chromium`), so a
# person can look at it as a browser shows it, offline.
#   scripts/screenshot-report.sh [SWEEP_DIR (default sweep-out)] [OUT.png] [WIDTH,HEIGHT]
# Checks that the report exists, that every local image it references exists and is not
# empty, and that the screenshot was written.
set -euo pipefail
DIR="${1:-sweep-out}"
OUT="${2:-$DIR/report-screenshot.png}"
SIZE="${3:-1400,6000}"
REPORT="$DIR/report.html"
[ -s "$REPORT" ] || { echo "no $REPORT (run: cargo run --release -- sweep --out $DIR)" >&2; exit 1; }
missing=0
while read -r src; do
  if [ ! -s "$DIR/$src" ]; then echo "missing or empty: $DIR/$src" >&2; missing=1; fi
done < <(grep -o 'src="[^"]*"' "$REPORT" | sed 's/^src="//; s/"$//' | sort -u)
[ "$missing" = 0 ] || exit 1
BROWSER="$(command -v chromium || command -v chromium-browser || command -v google-chrome || true)"
[ -n "$BROWSER" ] || { echo "no chromium (apt-get install -y chromium)" >&2; exit 1; }
FLAGS=(--headless --disable-gpu --hide-scrollbars --no-first-run --window-size="$SIZE" --screenshot="$(realpath -m "$OUT")")
[ "$(id -u)" = 0 ] && FLAGS+=(--no-sandbox)
"$BROWSER" "${FLAGS[@]}" "file://$(realpath "$REPORT")" >/dev/null 2>&1
[ -s "$OUT" ] || { echo "no screenshot written" >&2; exit 1; }
echo "wrote $OUT"
