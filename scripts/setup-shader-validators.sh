#!/bin/sh
# Installs the shader front ends the ibl-aniso snippet tests compile the emitted GLSL/HLSL/WGSL
# with: Khronos glslang (Debian apt, GLSL and HLSL) and naga (crates.io, WGSL).
set -e
if ! command -v glslangValidator >/dev/null 2>&1; then
    apt-get install -y --no-install-recommends glslang-tools ||
        { apt-get update -qq && apt-get install -y --no-install-recommends glslang-tools; }
fi
if ! command -v naga >/dev/null 2>&1; then
    cargo install --locked naga-cli
fi
