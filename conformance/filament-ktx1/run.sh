#!/usr/bin/env bash
# Filament's KTX1 reader on what `--target filament` writes, and on what it refuses: the
# default (R11F_G11F_B10F, glType 0x8C3A as cmgen writes it), rgba16f and rgba32f must load;
# a KTX1 RGB9E5 (written without the target, as `--layout ktx1 --format rgb9e5` does) must still
# abort, which is why `--target filament --format rgb9e5` is refused (google/filament
# libs/ktxreader/src/Ktx1Reader.cpp, toPixelDataType). Needs conformance/render/install.sh's
# node_modules (chromium, playwright-core, filament).
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-target/release}
ENV_MAP=${CONFORMANCE_ENV:-fixtures/hdri/interior_256.exr}
W=target/conformance/filament-ktx1
rm -rf "$W"
bash conformance/render/install.sh
args=()
for f in b10g11r11 rgba16f rgba32f; do
	"$BIN/prefilter" "$ENV_MAP" -o "$W/$f" --size 32 --target filament --format "$f" -q
	args+=("ok:$W/$f/env_ibl.ktx")
done
"$BIN/equirect-to-cube" "$ENV_MAP" -o "$W/skybox" --size 32 --target filament -q
args+=("ok:$W/skybox/env_skybox.ktx")
if "$BIN/prefilter" "$ENV_MAP" -o "$W/refused" --size 32 --target filament --format rgb9e5 -q 2> /dev/null; then
	echo "conformance/filament-ktx1: prefilter --target filament --format rgb9e5 was not refused" >&2
	exit 1
fi
"$BIN/prefilter" "$ENV_MAP" -o "$W/rgb9e5" --size 32 --layout ktx1 --format rgb9e5 -q
args+=("abort:$W/rgb9e5/prefilter.ktx")
node conformance/filament-ktx1/check.mjs "${args[@]}"
