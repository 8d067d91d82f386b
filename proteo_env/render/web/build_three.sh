#!/usr/bin/env bash
# Rebuild three.bundle.js from the npm registry (see README.md in this folder).
# Usage: proteo_env/render/web/build_three.sh [THREE_VERSION] [ESBUILD_VERSION]
set -euo pipefail
THREE_VERSION=${1:-0.187.0}
ESBUILD_VERSION=${2:-0.28.2}
HERE=$(cd "$(dirname "$0")" && pwd)
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
cd "$WORK"
npm init -y >/dev/null
npm install --no-audit --no-fund --silent "three@$THREE_VERSION" "esbuild@$ESBUILD_VERSION"
cp "$HERE/three_entry.js" .
./node_modules/.bin/esbuild three_entry.js --bundle --minify --format=iife --global-name=THREE \
  --legal-comments=inline --target=es2020 --log-level=warning \
  --banner:js="/* three.js $THREE_VERSION (npm three@$THREE_VERSION, MIT licence: THREE_LICENSE) bundled with esbuild $ESBUILD_VERSION from three_entry.js */" \
  --outfile="$HERE/three.bundle.js"
cp node_modules/three/LICENSE "$HERE/THREE_LICENSE"
echo "three.bundle.js: three $THREE_VERSION, $(wc -c < "$HERE/three.bundle.js") bytes"
