#!/usr/bin/env bash
# Rebuilds volec/report_assets/viewer.min.js: viewer_src.js bundled with three.js (from the npm
# registry, the pinned version below) by esbuild into one script that report.html inlines, and
# copies three.js's licence beside it. Needs node and npm; run it after editing viewer_src.js
# (tests/test_report.py checks that the bundle was made from the current source).
set -euo pipefail
THREE_VERSION=0.187.0
ESBUILD_VERSION=0.28.2
top=$(cd "$(dirname "$0")/.." && pwd)
assets="$top/volec/report_assets"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
npm init -y >/dev/null
npm install --silent --no-audit --no-fund "three@$THREE_VERSION" "esbuild@$ESBUILD_VERSION"
cp "$assets/viewer_src.js" viewer_src.js
digest=$(sha256sum viewer_src.js | cut -d' ' -f1)
npx esbuild viewer_src.js --bundle --minify --format=iife --target=es2020 \
  --legal-comments=none --log-level=warning --outfile=bundle.js
{
  echo "/* volec report viewer: viewer_src.js (sha256 $digest) bundled with three.js $THREE_VERSION"
  echo "   (MIT licence, see LICENSE-three.txt) by esbuild $ESBUILD_VERSION; scripts/vendor_viewer.sh */"
  cat bundle.js
} > "$assets/viewer.min.js"
cp node_modules/three/LICENSE "$assets/LICENSE-three.txt"
echo "wrote $assets/viewer.min.js ($(stat -c %s "$assets/viewer.min.js") bytes)"
