#!/usr/bin/env bash
# Installs what the render harness runs: Debian's `chromium` and `cmgen` (apt, when missing; a
# bundled browser cannot be downloaded here) and the pinned npm packages of package-lock.json
# (playwright-core, three, @babylonjs/core, filament, @khronosgroup/gltf-viewer, esbuild),
# reinstalled only when the lock changed (npm's cache keeps the downloads between runs).
set -euo pipefail
cd "$(dirname "$0")"
if ! command -v "${CHROMIUM:-chromium}" > /dev/null; then
	if [ "$(id -u)" != 0 ]; then
		echo "conformance/render: chromium is missing; install Debian's chromium (apt-get install chromium) or set CHROMIUM" >&2
		exit 1
	fi
	apt-get update -qq
	DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium > /dev/null
fi
# Filament's own route from a panorama is its native cmgen: Debian's (libfilament-tools).
if ! command -v cmgen > /dev/null; then
	if [ "$(id -u)" != 0 ]; then
		echo "conformance/render: cmgen is missing; install Debian's libfilament-tools (apt-get install libfilament-tools)" >&2
		exit 1
	fi
	DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libfilament-tools > /dev/null ||
		{ apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libfilament-tools > /dev/null; }
fi
want="$(sha256sum package-lock.json | cut -d' ' -f1)"
if [ "$(cat node_modules/.lock-sha256 2> /dev/null)" != "$want" ]; then
	npm ci --no-audit --no-fund --silent
	echo "$want" > node_modules/.lock-sha256
fi
