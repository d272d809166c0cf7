#!/usr/bin/env bash
# Bevy renders our `--target bevy` files with its own renderer (wgpu on Vulkan; here Mesa's
# llvmpipe from Debian's mesa-vulkan-drivers: no GPU, no window): for each fixture and the
# orientation panorama, `bevy-render` (conformance/bevy-render, Bevy 0.19.1, built apart from the
# workspace) draws the scene contract "sphere-rows v1" offscreen as the LOAD.txt snippet loads the
# files, reads the linear float image back (PFM), and compare.mjs holds it against the reference
# render of Bevy's BRDF (`render-ref --engine bevy`) and, for the orientation panorama, checks the
# patches.
#
# Skips (exit 0, with the reason printed) when no Vulkan ICD can be had, or when the Bevy build is
# not cached and BEVY_RENDER_BUILD=0 (the build's cost: docs/ENGINES.md, "Bevy, rendered by
# Bevy"). The build's target dir is kept where the machine keeps it between runs
# ($BEVY_RENDER_TARGET, default ~/.cache/ibl-bake/bevy-render-target).
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-target/release}
REF_RENDER=${REF_RENDER:-$BIN/render-ref}
W=target/conformance/bevy-render
BT=${BEVY_RENDER_TARGET:-${XDG_CACHE_HOME:-$HOME/.cache}/ibl-bake/bevy-render-target}
FIXTURES=${RENDER_FIXTURES:-"city_512 interior_256 studio_256"}
t0=$(date +%s)

icd=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json
if [ ! -e "$icd" ] && [ "$(id -u)" = 0 ]; then
	(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mesa-vulkan-drivers libvulkan1 > /dev/null) || true
fi
if [ ! -e "$icd" ]; then
	echo "conformance/bevy-render: skipped: no llvmpipe Vulkan ICD ($icd); install Debian's mesa-vulkan-drivers"
	exit 0
fi
exe="$BT/release/bevy-render-conformance"
if [ "${BEVY_RENDER_BUILD:-1}" = 0 ] && [ ! -x "$exe" ]; then
	echo "conformance/bevy-render: skipped: Bevy is not built in $BT and BEVY_RENDER_BUILD=0"
	exit 0
fi
# Lowest priority, 2 jobs (CI's cores; BEVY_RENDER_JOBS=1 on a shared machine): Bevy's 217 crates
# are the longest build of the project, ~22 CPU-minutes cold (docs/ENGINES.md), paid once: the
# target dir is kept between runs.
CARGO_TARGET_DIR="$BT" nice -n 19 cargo build --release -q -j "${BEVY_RENDER_JOBS:-2}" --locked \
	--manifest-path conformance/bevy-render/Cargo.toml
t1=$(date +%s)

# Only Mesa's software ICD: the render must not depend on which GPU drivers are installed.
export VK_ICD_FILENAMES="$icd" WGPU_BACKEND=vulkan
rm -rf "$W"
mkdir -p "$W"
envpath() { if [ "$1" = orientation ]; then echo "$W/orientation.exr"; else echo "fixtures/hdri/$1.exr"; fi; }
"$REF_RENDER" --orientation-panorama -o "$W/orientation.exr" -q
fail=0
for name in $FIXTURES orientation; do
	env="$(envpath "$name")"
	d="$W/$name"
	"$BIN/prefilter" "$env" -o "$d/spec" --target bevy -q
	"$BIN/irradiance" "$env" -o "$d/diff" --target bevy -q
	"$exe" "$d/spec/specular_rgb9e5_zstd.ktx2" "$d/diff/diffuse_rgb9e5_zstd.ktx2" "$d/bevy-ours.pfm" 2>"$d/bevy.log" || {
		echo "conformance/bevy-render: Bevy failed on $name:" >&2
		# The program's own one-line reason (Bevy's errors come with backtraces), else the log's end.
		grep '^bevy-render:' "$d/bevy.log" >&2 || grep -v '^\s*$' "$d/bevy.log" | tail -5 >&2
		fail=1
		continue
	}
	"$REF_RENDER" "$env" -o "$d/ref-bevy.pfm" --engine bevy --probes 0 -q
	if [ "$name" = orientation ]; then
		node conformance/render/compare.mjs "$d/ref-bevy.pfm" "$d/bevy-ours.pfm" --label "bevy ours|ref orientation" --patches 0.9 \
			--json "$d/bevy-ours.vs-ref.json" || fail=1
		node conformance/bevy-render/gate.mjs conformance/bevy-render/gates.txt "$name" "$d/bevy-ours.vs-ref.json" || fail=1
	else
		node conformance/render/compare.mjs "$d/ref-bevy.pfm" "$d/bevy-ours.pfm" --label "bevy ours|ref $name" \
			--json "$d/bevy-ours.vs-ref.json" || fail=1
		# Mean and p95 per group against the measured figures with margin (gates.txt).
		node conformance/bevy-render/gate.mjs conformance/bevy-render/gates.txt "$name" "$d/bevy-ours.vs-ref.json" || fail=1
	fi
done
t2=$(date +%s)
echo "conformance/bevy-render: build $((t1 - t0)) s, bake+render+compare $((t2 - t1)) s"
if [ "$fail" != 0 ]; then
	echo "conformance/bevy-render: Bevy's render of our files is off (see above)" >&2
	exit 1
fi
