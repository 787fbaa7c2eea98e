#!/usr/bin/env bash
# Vendors the status page's plotting library (uPlot) into the repository:
# installs exactly what web/package-lock.json pins with `npm ci` and copies
# the minified script, its style sheet and its licence into
# src/serve/page/vendor/, which the binary embeds (src/serve/page.rs).
# The copied files are checked in: building motorbench needs neither npm
# nor a network. Run this after changing web/package.json (then
# `npm install --package-lock-only` in web/ updates the lock) and commit
# the result.
set -euo pipefail
cd "$(dirname "$0")/../web"
npm ci --ignore-scripts --no-audit --no-fund
dest=../src/serve/page/vendor
mkdir -p "$dest"
cp node_modules/uplot/dist/uPlot.iife.min.js "$dest/uPlot.iife.min.js"
cp node_modules/uplot/dist/uPlot.min.css "$dest/uPlot.min.css"
cp node_modules/uplot/LICENSE "$dest/LICENSE-uPlot"
version=$(node -p 'require("./node_modules/uplot/package.json").version')
echo "uPlot $version" > "$dest/VERSION"
echo "vendored uPlot $version into src/serve/page/vendor"
