#!/usr/bin/env bash
# Installs what `make ray-test` needs into the current Python: Ray and pytest from PyPI, and
# the bake-ray package from python/ (with its `ray` extra). Idempotent: quick when present.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
# The Ray the tests run: one version, so that a new release on PyPI cannot change what CI runs
# (bake-ray itself asks only ray>=2.9). 2.60.0 is what PyPI gave the last recorded CI runs
# (docs/notes/ci-history.md); RAY_VERSION=... tries another.
RAY_VERSION=${RAY_VERSION:-2.60.0}
if ! "$PYTHON" -c 'import sys, ray, pytest, wheel, setuptools.build_meta; sys.exit(ray.__version__ != sys.argv[1])' "$RAY_VERSION" >/dev/null 2>&1 \
	|| ! "$PYTHON" -c 'import setuptools, sys; sys.exit(int(setuptools.__version__.split(".")[0]) < 61)'; then
	echo "setup-ray: installing ray, pytest and the packaging tools from PyPI (once)"
	"$PYTHON" -m pip install --quiet --disable-pip-version-check --root-user-action=ignore \
		"ray==$RAY_VERSION" 'pytest>=7' 'setuptools>=61' wheel
fi
# The package itself is tiny: reinstall it every time so edits are picked up (no network).
"$PYTHON" -m pip install --quiet --disable-pip-version-check --root-user-action=ignore \
	--no-deps --no-build-isolation ./python
"$PYTHON" -c 'import ray, bake_ray; print("setup-ray: ray", ray.__version__, "and bake-ray", bake_ray.__version__, "ready")'
