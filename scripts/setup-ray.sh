#!/usr/bin/env bash
# Installs what `make ray-test` needs into the current Python: Ray and pytest from PyPI, and
# the bake-ray package from python/ (with its `ray` extra). Idempotent: quick when present.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
if ! "$PYTHON" -c 'import ray, pytest' >/dev/null 2>&1; then
	echo "setup-ray: installing ray and pytest from PyPI (once)"
	"$PYTHON" -m pip install --quiet --disable-pip-version-check 'ray>=2.9' 'pytest>=7'
fi
# The package itself is tiny: reinstall it every time so edits are picked up.
"$PYTHON" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation ./python 2>/dev/null \
	|| "$PYTHON" -m pip install --quiet --disable-pip-version-check --no-deps ./python
"$PYTHON" -c 'import ray, bake_ray; print("setup-ray: ray", ray.__version__, "and bake-ray", bake_ray.__version__, "ready")'
