#!/usr/bin/env bash
# Installs the engines these checks run (three, @babylonjs/core, pinned in package.json and
# package-lock.json) from the npm registry.
set -euo pipefail
cd "$(dirname "$0")"
npm ci --no-audit --no-fund || npm install --no-audit --no-fund
