#!/usr/bin/env bash
# `make conformance-engines`: bakes fresh outputs with the release binaries and has the engines'
# own code read them in node (three.js: ObjectLoader + SphericalHarmonics3 on our LightProbe;
# Babylon.js: its .env parser and SphericalPolynomial on our environment.env), each compared
# with our irradiance cube as that engine samples it.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
cd "$root"
cargo build --release -q -p irradiance -p prefilter
bash conformance/engines/install.sh > /dev/null
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
for env in fixtures/hdri/city_512.exr fixtures/hdri/interior_256.exr fixtures/hdri/studio_256.exr; do
	name="$(basename "$env" .exr)"
	echo "== $name"
	target/release/irradiance "$env" -o "$tmp/$name/three" --target three --layout ktx2 --size 16 -q
	node conformance/engines/three_probe.mjs "$tmp/$name/three"
	target/release/prefilter "$env" -o "$tmp/$name/babylon" --target babylon --size 64 -q
	target/release/irradiance "$env" -o "$tmp/$name/babylon-irradiance" --target babylon --layout ktx2 --size 16 -q
	node conformance/engines/babylon_env.mjs "$tmp/$name/babylon/environment.env" "$tmp/$name/babylon-irradiance/irradiance.ktx2"
done
echo "conformance-engines: three.js and Babylon.js read every output as baked"
