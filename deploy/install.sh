#!/usr/bin/env bash
# Install what is missing: Debian packages, then a .venv with CloudSim (and the bundled
# distributions in simulator/ and router/) in editable mode. Fast and silent when nothing changed since the last run.
set -euo pipefail
cd "$(dirname "$0")/.."

python=${PYTHON:-python3}
venv=.venv
stamp=$venv/.install-stamp
# One line per step on the terminal; what apt, npm and pip print goes to this file.
log=.install.log

logged() {
    echo "--- $(date -u +%FT%TZ) $*" >>"$log"
    if ! "$@" >>"$log" 2>&1; then
        echo "install: failed: $*" >&2
        echo "install: the last lines of $log:" >&2
        tail -n 25 "$log" >&2
        exit 1
    fi
}

want_apt=$(grep -Ev '^\s*(#|$)' deploy/apt-packages.txt)
missing=()
for pkg in $want_apt; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
    if [ "$(id -u)" != 0 ]; then
        echo "install: missing Debian packages (${missing[*]}); run as root or install them" >&2
        exit 1
    fi
    echo "install: Debian packages: ${missing[*]} (output: $log)"
    # Keep apt from starting redis, sshd, ... in this namespace: CloudSim starts its own.
    policy=/usr/sbin/policy-rc.d
    made_policy=0
    if [ ! -e "$policy" ]; then
        printf '#!/bin/sh\nexit 101\n' >"$policy" && chmod +x "$policy" && made_policy=1
    fi
    logged apt-get update -qq
    logged env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
    [ "$made_policy" = 1 ] && rm -f "$policy"
fi

# Browser libraries (three.js for the run viewer) from the npm registry, pinned by
# package-lock.json, copied to where the app serves static files: pages never fetch elsewhere.
vendor=templates/web/static/vendor
npm_digest=$(cat package.json package-lock.json | sha256sum | cut -c1-16)
if [ ! -f "$vendor/.stamp" ] || [ "$(cat "$vendor/.stamp")" != "$npm_digest" ]; then
    if ! command -v npm >/dev/null; then
        # Debian's nodejs comes without npm (nodesource's carries it): add Debian's npm
        [ "$(id -u)" = 0 ] || { echo "install: npm is missing; install it (apt-get install npm)" >&2; exit 1; }
        echo "install: Debian package npm (output: $log)"
        logged apt-get update -qq  # the package block above may not have run: no lists yet
        logged env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends npm
    fi
    echo "install: three.js from the npm registry (output: $log)"
    logged npm ci --no-audit --no-fund --ignore-scripts --loglevel=error
    mkdir -p "$vendor/three"
    cp node_modules/three/build/three.module.js node_modules/three/build/three.core.js \
        node_modules/three/examples/jsm/controls/OrbitControls.js node_modules/three/LICENSE \
        "$vendor/three/"
    echo "$npm_digest" >"$vendor/.stamp"
fi

# The orchestrator, and the distributions it installs onto machines (for their tests).
subprojects=()
for sub in simulator router; do
    [ -f "$sub/pyproject.toml" ] && subprojects+=("$sub")
done
manifests=(pyproject.toml)
for sub in "${subprojects[@]}"; do manifests+=("$sub/pyproject.toml"); done
digest=$(cat "${manifests[@]}" | sha256sum | cut -c1-16)
if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$digest" ]; then
    exit 0
fi
echo "install: $venv with CloudSim and its Python packages (output: $log)"
[ -x "$venv/bin/python" ] || logged "$python" -m venv "$venv"
logged "$venv/bin/pip" install -q --upgrade pip
targets=(-e ".[dev]")
for sub in "${subprojects[@]}"; do targets+=(-e "./$sub"); done
logged "$venv/bin/pip" install -q "${targets[@]}"
echo "$digest" >"$stamp"
echo "install: done"
