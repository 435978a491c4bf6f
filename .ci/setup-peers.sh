#!/usr/bin/env bash
# .ci/setup-peers.sh - install and build the peer fixtures of tests/peers/.
#
# Also installs tshark (apt), which decodes the captures of `ferrobus sniff`.
# For the MQTT bridge's tests (tests/peers/sparkplug/): mosquitto, the broker the
# tests start themselves, and protobuf-compiler (`protoc --decode_raw`) from apt;
# pysparkplug==0.6.1 (it pins paho-mqtt<2 itself) in its own venv,
# target/peers/sparkplug-venv, kept out of the system Python where pymodbus
# lives (python3-venv from apt makes it); and Eclipse Tahu's JavaScript codec
# (npm sparkplug-payload, pinned by tests/peers/sparkplug/tahu/package-lock.json;
# nodejs and npm from apt when missing).
# Installs what the peers need (apt: socat, libmodbus-dev, mbpoll, libudev-dev,
# pkg-config, gcc, chromium for the status page; pip: pymodbus==3.16.1, pyserial==3.5,
# pysunspec2==1.3.7, prometheus-client==0.26.0 for the metrics), compiles the
# libmodbus fixtures into target/peers/ and builds tokio-modbus-peer (release,
# its own target dir target/peers/tokio-modbus-peer, --locked). Prints a
# one-line version summary at the end.
#
# Idempotent and non-interactive: installed packages are left alone, the
# fixtures are rebuilt every run (that takes seconds). Runs as root, or via
# sudo for apt-get when not root.
#
# With CI=true every missing piece is a hard failure (exit 1) at the point it
# is found. Without CI a missing piece is reported as WARNING, the rest is
# still set up, and the script exits 0 after saying what is missing - so a
# developer without sudo can still build the fixtures that do not need it.
#
# The Rust toolchain (cargo) is expected to be there already (rustup, or the
# CI's Rust setup step); python3 and pip are installed with apt if missing.
# Environment: PYTHON (default python3), CARGO (default cargo).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PEERS_SRC="$ROOT/tests/peers"
OUT="$ROOT/target/peers"
PYTHON="${PYTHON:-python3}"
CARGO="${CARGO:-cargo}"
PYMODBUS_VERSION="3.16.1"
PYSERIAL_VERSION="3.5"
# pysunspec2: the SunSpec Alliance's own client, and the source of the model
# definitions crates/ferrobus-sunspec embeds at build time (sunspec2/models/json).
PYSUNSPEC2_VERSION="1.3.7"
# prometheus_client's OpenMetrics parser reads what `--metrics` serves, as Prometheus would.
PROMETHEUS_CLIENT_VERSION="0.26.0"
APT_PACKAGES=(socat libmodbus-dev mbpoll libudev-dev pkg-config gcc)
# tshark decodes the captures of `ferrobus sniff` in its tests.
APT_PACKAGES+=(tshark)
# openssl: the Modbus/TCP Security interop test makes a client certificate with it.
APT_PACKAGES+=(openssl)
# The man page tests render with `man -l` (man-db) and groff's nroff.
APT_PACKAGES+=(man-db groff-base)
# The completion tests load the zsh script too (bash is there already).
APT_PACKAGES+=(zsh)
# tmux is the terminal emulator of `ferrobus monitor`'s end-to-end test.
APT_PACKAGES+=(tmux)
# The bridge's tests: their own broker, protoc for the raw payload, and the venv for pysparkplug.
APT_PACKAGES+=(mosquitto protobuf-compiler python3-venv)
# The status page (`--metrics`) is tested in a real browser: headless Chromium runs its script.
APT_PACKAGES+=(chromium)
PYSPARKPLUG_VERSION="0.6.1"
SPARKPLUG_VENV="$OUT/sparkplug-venv"
export DEBIAN_FRONTEND=noninteractive

IN_CI=false
case "${CI:-}" in true | TRUE | True | 1 | yes) IN_CI=true ;; esac

MISSING=()
log() { printf 'setup-peers: %s\n' "$*" >&2; }
# missing NAME MESSAGE...: a piece could not be installed or built.
missing() {
    local what="$1"
    shift
    if $IN_CI; then
        log "ERROR: $* (CI=true: failing)"
        exit 1
    fi
    log "WARNING: $* (continuing; CI would fail here)"
    MISSING+=("$what")
}
have() { command -v "$1" >/dev/null 2>&1; }

# ---- privileges --------------------------------------------------------------
# Never prompt: sudo -n fails instead of asking for a password.
SUDO=()
if [ "$(id -u)" -ne 0 ]; then
    if have sudo && sudo -n true 2>/dev/null; then
        SUDO=(sudo -n)
    else
        SUDO=(false) # no way to install system packages
    fi
fi

# ---- apt packages ------------------------------------------------------------
apt_install() { # apt_install PKG...: best effort, the caller checks the result
    [ "${SUDO[0]:-}" != false ] && have apt-get || return 1
    "${SUDO[@]}" apt-get update -qq &&
        "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
            --no-install-recommends "$@" >/dev/null
}

pkg_installed() {
    dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q 'install ok installed'
}

# tshark's package asks whether non-root users may capture; answer no, without a prompt.
if have debconf-set-selections && [ "${SUDO[0]:-}" != false ]; then
    echo "wireshark-common wireshark-common/install-setuid boolean false" |
        "${SUDO[@]}" debconf-set-selections || true
fi

if have dpkg-query && have apt-get; then
    NEED=()
    for p in "${APT_PACKAGES[@]}"; do
        pkg_installed "$p" || NEED+=("$p")
    done
    if [ "${#NEED[@]}" -gt 0 ]; then
        log "apt-get install ${NEED[*]}"
        if [ "${SUDO[0]:-}" = false ]; then
            missing "${NEED[*]}" "not root and no passwordless sudo: cannot install ${NEED[*]}"
        elif ! apt_install "${NEED[@]}"; then
            missing "${NEED[*]}" "apt-get install ${NEED[*]} failed"
        fi
    fi
else
    for p in "${APT_PACKAGES[@]}"; do
        # Without apt, accept the tools if they are there anyway.
        case "$p" in
        libmodbus-dev) pkg-config --exists libmodbus 2>/dev/null || missing libmodbus-dev "no apt-get and no libmodbus" ;;
        libudev-dev) ;; # only needed for serial port enumeration, which the peers do not use
        *) have "$p" || missing "$p" "no apt-get and no $p" ;;
        esac
    done
fi

# ---- python packages ---------------------------------------------------------
py_versions_ok() {
    "$PYTHON" - "$PYMODBUS_VERSION" "$PYSUNSPEC2_VERSION" "$PROMETHEUS_CLIENT_VERSION" <<'EOF' 2>/dev/null
import sys
from importlib.metadata import version
import pymodbus, serial, sunspec2, prometheus_client
found = (pymodbus.__version__, version("pysunspec2"), version("prometheus-client"))
sys.exit(0 if found == tuple(sys.argv[1:4]) else 1)
EOF
}

if ! py_versions_ok; then
    # A fresh Debian image may have neither python3 nor pip.
    if ! have "$PYTHON" || ! "$PYTHON" -m pip --version >/dev/null 2>&1; then
        log "apt-get install python3 python3-pip"
        apt_install python3 python3-pip || true
    fi
    if ! have "$PYTHON"; then
        missing python3 "$PYTHON not found and could not be installed"
    else
        PIP=("$PYTHON" -m pip install --quiet --disable-pip-version-check
            "pymodbus==$PYMODBUS_VERSION" "pyserial==$PYSERIAL_VERSION" "pysunspec2==$PYSUNSPEC2_VERSION"
            "prometheus-client==$PROMETHEUS_CLIENT_VERSION")
        log "${PIP[*]}"
        PIP_LOG="$(mktemp)"
        if ! "${PIP[@]}" >"$PIP_LOG" 2>&1; then
            # Debian's system Python refuses plain pip installs (PEP 668).
            if grep -q 'externally-managed-environment' "$PIP_LOG"; then
                log "pip: externally managed environment, retrying with --break-system-packages"
                "${PIP[@]}" --break-system-packages >"$PIP_LOG" 2>&1 || true
            fi
        fi
        if ! py_versions_ok; then
            cat "$PIP_LOG" >&2
            rm -f "$PIP_LOG"
            missing pymodbus "cannot install pymodbus==$PYMODBUS_VERSION / pyserial==$PYSERIAL_VERSION / pysunspec2==$PYSUNSPEC2_VERSION / prometheus-client==$PROMETHEUS_CLIENT_VERSION for $PYTHON"
        fi
        rm -f "$PIP_LOG"
    fi
fi

# ---- pysparkplug venv --------------------------------------------------------
sparkplug_ok() {
    "$SPARKPLUG_VENV/bin/python" - "$PYSPARKPLUG_VERSION" <<'EOF' 2>/dev/null
import sys
import paho.mqtt.client, pysparkplug
sys.exit(0 if pysparkplug.__version__ == sys.argv[1] else 1)
EOF
}

if ! sparkplug_ok; then
    log "venv $SPARKPLUG_VENV: pip install pysparkplug==$PYSPARKPLUG_VERSION"
    mkdir -p "$OUT"
    VENV_LOG="$(mktemp)"
    if ! { "$PYTHON" -m venv "$SPARKPLUG_VENV" &&
        "$SPARKPLUG_VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
            "pysparkplug==$PYSPARKPLUG_VERSION"; } >"$VENV_LOG" 2>&1 || ! sparkplug_ok; then
        cat "$VENV_LOG" >&2
        missing pysparkplug "cannot make $SPARKPLUG_VENV with pysparkplug==$PYSPARKPLUG_VERSION"
    fi
    rm -f "$VENV_LOG"
fi

# ---- libmodbus fixtures ------------------------------------------------------
mkdir -p "$OUT"
if have gcc && pkg-config --exists libmodbus 2>/dev/null; then
    read -r -a MODBUS_FLAGS <<<"$(pkg-config --cflags --libs libmodbus)"
    for f in libmodbus_server libmodbus_client; do
        # Sources before the libraries: with --as-needed the order matters.
        if ! gcc -O2 -Wall -Wextra -Werror "$PEERS_SRC/$f.c" "${MODBUS_FLAGS[@]}" -o "$OUT/$f.tmp"; then
            missing "$f" "gcc failed for tests/peers/$f.c"
            continue
        fi
        mv -f "$OUT/$f.tmp" "$OUT/$f"
    done
else
    missing libmodbus-fixtures "gcc or libmodbus (pkg-config) missing: C fixtures not built"
fi

# ---- tokio-modbus-peer -------------------------------------------------------
if have "$CARGO"; then
    log "cargo build --release tokio-modbus-peer"
    if ! "$CARGO" build --quiet --release --locked \
        --manifest-path "$PEERS_SRC/tokio-modbus-peer/Cargo.toml" \
        --target-dir "$OUT/tokio-modbus-peer"; then
        missing tokio-modbus-peer "cargo build of tests/peers/tokio-modbus-peer failed"
    fi
else
    missing tokio-modbus-peer "cargo not found"
fi

# ---- Eclipse Tahu's JavaScript codec (tests/peers/sparkplug/tahu) ------------
# npm sparkplug-payload 1.0.3 (EPL-2.0), pinned by its package-lock.json: the third Sparkplug
# decoder of crates/ferrobus-bridge/tests/tahu.rs. node and npm come from apt when missing.
TAHU_DIR="$PEERS_SRC/sparkplug/tahu"
if ! have node || ! have npm; then
    log "apt-get install nodejs npm"
    apt_install nodejs npm || true
fi
if ! have node || ! have npm; then
    missing nodejs "node or npm not found and could not be installed: no Tahu codec"
else
    log "npm ci in tests/peers/sparkplug/tahu"
    if ! (cd "$TAHU_DIR" && npm ci --no-audit --no-fund --loglevel=error >/dev/null); then
        missing sparkplug-payload "npm ci in tests/peers/sparkplug/tahu failed"
    elif ! (cd "$TAHU_DIR" && node -e 'require("sparkplug-payload")'); then
        missing sparkplug-payload "sparkplug-payload does not load in node $(node --version)"
    fi
fi

# ---- check and summarise -----------------------------------------------------
for bin in "$OUT/libmodbus_server" "$OUT/libmodbus_client" "$OUT/tokio-modbus-peer/release/tokio-modbus-peer"; do
    [ -x "$bin" ] || missing "$(basename "$bin")" "$bin was not built"
done
for tool in socat mbpoll; do
    have "$tool" || missing "$tool" "$tool not installed"
done
have tshark || missing tshark "tshark not installed"
MOSQUITTO=/usr/sbin/mosquitto
[ -x "$MOSQUITTO" ] || MOSQUITTO="$(command -v mosquitto || true)"
[ -n "$MOSQUITTO" ] || missing mosquitto "mosquitto not installed"
have protoc || missing protoc "protoc (protobuf-compiler) not installed"

v_libmodbus="$(pkg-config --modversion libmodbus 2>/dev/null || echo missing)"
v_pymodbus="$("$PYTHON" -c 'import pymodbus; print(pymodbus.__version__)' 2>/dev/null || echo missing)"
v_pyserial="$("$PYTHON" -c 'import serial; print(serial.__version__)' 2>/dev/null || echo missing)"
v_pysunspec2="$("$PYTHON" -c 'from importlib.metadata import version; print(version("pysunspec2"))' 2>/dev/null || echo missing)"
v_python="$("$PYTHON" -c 'import platform; print(platform.python_version())' 2>/dev/null || echo missing)"
v_tokio_modbus="$(awk '/^name = "tokio-modbus"$/ { getline; gsub(/"/, "", $3); print $3; exit }' \
    "$PEERS_SRC/tokio-modbus-peer/Cargo.lock" 2>/dev/null)"
v_socat="$(socat -V 2>/dev/null | awk '/socat version/ { print $3; exit }')"
v_mbpoll="$(dpkg-query -W -f='${Version}' mbpoll 2>/dev/null || echo '?')"
v_gcc="$(gcc -dumpfullversion 2>/dev/null || echo missing)"
v_rustc="$(rustc --version 2>/dev/null | awk '{ print $2 }')"

echo "peers: libmodbus ${v_libmodbus}, pymodbus ${v_pymodbus} (python ${v_python}, pyserial ${v_pyserial}), pysunspec2 ${v_pysunspec2}," \
    "tokio-modbus ${v_tokio_modbus:-?} (rustc ${v_rustc:-missing}), socat ${v_socat:-missing}," \
    "mbpoll ${v_mbpoll}, gcc ${v_gcc} -> target/peers/"

v_chromium="$(chromium --version 2>/dev/null || echo 'chromium missing')"
v_promclient="$("$PYTHON" -c 'from importlib.metadata import version; print(version("prometheus-client"))' 2>/dev/null || echo missing)"
echo "peers: ${v_chromium}, prometheus-client ${v_promclient}"

v_tshark="$(tshark --version 2>/dev/null || true)"
v_tshark="${v_tshark%%$'\n'*}"
echo "peers: ${v_tshark:-tshark missing}"

v_tahu="$(cd "$TAHU_DIR" 2>/dev/null && node -p 'require("sparkplug-payload/package.json").version' 2>/dev/null || echo missing)"
echo "peers: sparkplug-payload ${v_tahu} (Eclipse Tahu JS; node $(node --version 2>/dev/null || echo missing), npm $(npm --version 2>/dev/null || echo missing))"
v_mosquitto="$("${MOSQUITTO:-mosquitto}" -h 2>/dev/null | awk '/^mosquitto version/ { print $3; exit }' || true)"
v_protoc="$(protoc --version 2>/dev/null | awk '{ print $2 }' || true)"
v_pysparkplug="$("$SPARKPLUG_VENV/bin/python" -c 'import pysparkplug; print(pysparkplug.__version__)' 2>/dev/null || echo missing)"
v_paho="$("$SPARKPLUG_VENV/bin/python" -c 'import paho.mqtt; print(paho.mqtt.__version__)' 2>/dev/null || echo missing)"
echo "peers: mosquitto ${v_mosquitto:-missing}, protoc ${v_protoc:-missing}," \
    "pysparkplug ${v_pysparkplug} (paho-mqtt ${v_paho}) -> target/peers/sparkplug-venv"

if [ "${#MISSING[@]}" -gt 0 ]; then
    log "WARNING: incomplete setup, missing: ${MISSING[*]}"
fi
exit 0
