#!/usr/bin/env bash
# `make conformance`: what the bakes write, checked by code that is not ours (libktx, the
# ktx2 crate, ktx-parse, imagecodecs, a spec-written numpy decoder), and files written by code
# that is not ours read back by our tools. Installs what it needs from PyPI and npm into
# target/conformance (kept between runs). See conformance/README.md.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release}
WORK=target/conformance
ENV_MAP=${CONFORMANCE_ENV:-fixtures/hdri/interior_256.exr}
mkdir -p "$WORK"

if [ ! -x "$WORK/venv/bin/python" ]; then
	python3 -m venv "$WORK/venv"
fi
"$WORK/venv/bin/pip" install -q --disable-pip-version-check -r conformance/requirements.txt
(cd conformance && npm ci --no-audit --no-fund --silent)

# The matrix: every tool that writes a cube × every container × every format.
BAKES="$WORK/bakes"
rm -rf "$BAKES"
for tool in prefilter equirect-to-cube irradiance; do
	case $tool in
	prefilter) size=(--size 64 --levels 4) ;;
	equirect-to-cube) size=(--size 32) ;;
	irradiance) size=(--size 16) ;;
	esac
	for container in ktx2 ktx2-zstd dds ktx1; do
		case $container in
		ktx2-zstd) layout=(--layout ktx2 --zstd 19) ;;
		*) layout=(--layout "$container") ;;
		esac
		for format in rgba32f rgba16f rgb9e5 b10g11r11 bc6h; do
			"$BIN/$tool" "$ENV_MAP" -o "$BAKES/$tool/$container-$format" "${size[@]}" "${layout[@]}" --format "$format" -q
		done
	done
	# And as EXR faces, float and half (read by OpenEXR against the float KTX2).
	for format in rgba32f rgba16f; do
		"$BIN/$tool" "$ENV_MAP" -o "$BAKES/$tool/exr-$format" "${size[@]}" --layout faces --format "$format" -q
	done
done
echo "baked $(find "$BAKES" -type f | wc -l) files from $ENV_MAP"
"$WORK/venv/bin/python" conformance/containers.py "$BAKES" "$BIN"

# Engine targets as the engines' loaders read them: libktx (Filament's KTX1 and its `sh`
# metadata, Bevy's and glTF's KTX2), then Bevy's own loader (bevy_image, built apart from the
# workspace), then three.js and Babylon.js in node (conformance/engines).
T="$WORK/targets"
rm -rf "$T"
for t in gltf bevy filament unity; do
	"$BIN/prefilter" "$ENV_MAP" -o "$T/$t" --size 64 --target "$t" -q
	"$BIN/irradiance" "$ENV_MAP" -o "$T/$t-irr" --size 16 --target "$t" -q
	"$BIN/equirect-to-cube" "$ENV_MAP" -o "$T/$t-cube" --size 32 --target "$t" -q
done
"$BIN/prefilter" "$ENV_MAP" -o "$T/gltf-ktx2" --size 64 --layout ktx2 --half -q
(cd conformance && "../$WORK/venv/bin/python" targets.py "../$T" "../$BAKES")
CARGO_TARGET_DIR="$PWD/$WORK/bevy-target" cargo build --release -q --manifest-path conformance/bevy/Cargo.toml
xargs "$WORK/bevy-target/release/bevy-conformance" < "$T/bevy-args.txt"
bash conformance/engines/run.sh
bash conformance/render/run.sh
# The emitted GLSL (custom lookup, anisotropic FIS) run in WebGL2 against the CPU emulation.
bash conformance/render/shader-check.sh
# Bevy's own renderer (wgpu on Mesa's llvmpipe Vulkan) on our --target bevy files. Its cold build
# is ~22 CPU-minutes (1325 s measured, docs/ENGINES.md "Bevy, rendered by Bevy"), inside CI's
# budget at -j 2 and paid once (target dir cached in ~/.cache/ibl-bake/bevy-render-target);
# BEVY_RENDER=0 skips it. The bevy_image checks above run always.
if [ "${BEVY_RENDER:-1}" != 0 ]; then
	bash conformance/bevy-render/run.sh
else
	echo "conformance: Bevy render skipped (BEVY_RENDER=0)"
fi
# Filament's own KTX1 reader (wasm, in the same Chromium) loads every format --target filament
# writes, and still aborts on the KTX1 RGB9E5 that target refuses.
bash conformance/filament-ktx1/run.sh
