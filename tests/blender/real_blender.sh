#!/usr/bin/env bash
# make test-blender: run tests/blender under a real `blender -b` binary.
#
# PyPI has only the bpy module; this machine's Debian release packages Blender 3.4, too
# old for extensions.  Debian trixie packages Blender 4.3.2 (Python 3.13, numpy 2.2), so
# this script keeps a debootstrap chroot of trixie with its `blender` package, cached
# OUTSIDE the checkout (CI clones afresh each run):
#
#   $RELRAY_CACHE (default ~/.cache/relray)/trixie-blender/       the chroot
#     opt/relray-py313/     cp313 wheels of the core's dependencies, from PyPI
#     opt/relray-src/relray the checkout, bind-mounted while the tests run
#
# The first run needs root, network access to Debian and PyPI, about 3-5 minutes and
# 2.5 GB.  Every failure says what is missing and exits non-zero: this script never
# passes silently.  What it mounts it unmounts, also on failure or interruption.
#
# Usage: tests/blender/real_blender.sh [setup|run|all] [extra pytest args...]
set -euo pipefail

REPO="$(cd "$(dirname "$0")/../.." && pwd)"
CACHE="${RELRAY_CACHE:-$HOME/.cache/relray}"
ROOT="$CACHE/trixie-blender"
PYBIN="${PYBIN:-$REPO/.venv/bin/python}"
SUITE=trixie
# Debian packages inside the chroot.  python3-scipy, -pil and -typing-extensions are the
# numpy-2 builds of colour-science's dependencies (Debian's, to match its numpy 2.2).
APT_PACKAGES="blender python3-numpy python3-pytest python3-scipy python3-pil python3-typing-extensions"
# The extension's bundled packages (relblend/packaging.py's WHEEL_PACKAGES) as cp313
# manylinux wheels from PyPI, the same versions as in .venv, i.e. requirements.lock (numba
# and embreex accept numpy 2.2), except those Debian provides above as numpy-2 builds.
# typing_extensions comes from the lock too: pydantic-core needs a newer one (Sentinel)
# than Debian's (it is pure Python, so /opt/relray-py313's copy simply wins).
DEBIAN_PROVIDED="scipy pillow"
CHROOT_RECIPE="v1 $SUITE $APT_PACKAGES"

say() { echo "test-blender: $*"; }
die() {  # a setup step failed: the tests could not run at all
    echo "" >&2
    echo "test-blender: FAILED: $*" >&2
    echo "test-blender: the real-Blender tests did NOT run." >&2
    exit 1
}
fail() {  # the tests ran and failed
    echo "" >&2
    echo "test-blender: FAILED: $*" >&2
    exit 1
}

[ "$(id -u)" = 0 ] || die "needs root (debootstrap, mount, chroot); run as root or skip make test-blender knowingly"
[ -x "$PYBIN" ] || die "$PYBIN not found: run 'make venv' first"

MOUNTS=()
cleanup() {
    local rc=$? m
    for ((i = ${#MOUNTS[@]} - 1; i >= 0; i--)); do
        m="${MOUNTS[$i]}"
        if mountpoint -q "$m"; then
            umount "$m" 2>/dev/null || umount -l "$m" || echo "test-blender: WARNING: could not unmount $m" >&2
        fi
    done
    MOUNTS=()
    exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

mount_bind() {  # mount_bind SRC DST [ro]
    mkdir -p "$2"
    mountpoint -q "$2" && umount "$2"
    mount --bind "$1" "$2"
    MOUNTS+=("$2")
    if [ "${3:-}" = ro ]; then mount -o remount,bind,ro "$2"; fi
}

mount_proc() {  # mount_proc CHROOT
    mkdir -p "$1/proc"
    mountpoint -q "$1/proc" || mount -t proc proc "$1/proc"
    MOUNTS+=("$1/proc")
}

unmount_all_under() {  # before deleting a chroot: never rm -rf through a bind mount
    local dir m
    dir="$(readlink -f "$1")"
    for m in $(awk '{print $2}' /proc/mounts | grep -E "^$dir(/|$)" | sort -r); do
        umount "$m" 2>/dev/null || umount -l "$m" || true
    done
    if awk '{print $2}' /proc/mounts | grep -qE "^$dir(/|$)"; then
        die "something is still mounted under $dir; unmount it by hand before it is deleted"
    fi
}

debian_mirror() {
    # The Debian mirror the machine's own apt sources name (deb822 or one-line format),
    # unless RELRAY_DEBIAN_MIRROR says otherwise.
    local m="${RELRAY_DEBIAN_MIRROR:-}"
    if [ -z "$m" ] && [ -f /etc/apt/sources.list.d/debian.sources ]; then
        m=$(awk '/^URIs:/ {print $2; exit}' /etc/apt/sources.list.d/debian.sources)
    fi
    if [ -z "$m" ] && [ -f /etc/apt/sources.list ]; then
        m=$(awk '$1 == "deb" && $2 !~ /security/ {print $2; exit}' /etc/apt/sources.list)
    fi
    echo "${m:-http://deb.debian.org/debian}"
}

# A virtual display for the interactive-Blender tests (test_viewport_draw.py): Xvfb,
# Mesa's software OpenGL (llvmpipe, OpenGL 4.5) and xwd to capture the screen. Added to
# a cached chroot with apt-get (seconds) instead of rebuilding it.
DISPLAY_PACKAGES="xvfb xauth x11-apps libgl1-mesa-dri libglx-mesa0 libegl-mesa0"

chroot_apt_install() {  # chroot_apt_install DIR LOG PACKAGES...: apt-get in the chroot
    local dir="$1" log="$2"
    shift 2
    cp /etc/resolv.conf "$dir/etc/resolv.conf"
    mount_proc "$dir"
    chroot "$dir" /usr/bin/env DEBIAN_FRONTEND=noninteractive \
        sh -c "apt-get update -q && apt-get install -y -q --no-install-recommends $*" \
        >"$log" 2>&1 || die "apt-get install of '$*' in the chroot failed (log: $log)"
}

ensure_display_packages() {
    local stamp="$ROOT/.relray-display"
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$DISPLAY_PACKAGES" ]; then
        return
    fi
    say "installing the virtual display into the chroot: $DISPLAY_PACKAGES"
    # shellcheck disable=SC2086
    chroot_apt_install "$ROOT" "$CACHE/chroot-display-apt.log" $DISPLAY_PACKAGES
    echo "$DISPLAY_PACKAGES" >"$stamp"
}

build_chroot() {
    if [ -f "$ROOT/.relray-chroot" ] && [ "$(cat "$ROOT/.relray-chroot")" = "$CHROOT_RECIPE" ]; then
        say "chroot cached at $ROOT"
        ensure_display_packages
        return
    fi
    local tmp="$ROOT.tmp" mirror
    mirror=$(debian_mirror)
    say "building a Debian $SUITE chroot with blender at $ROOT (once; about 3-5 minutes, 2.5 GB)"
    if ! command -v debootstrap >/dev/null; then
        (apt-get install -y debootstrap || { apt-get update && apt-get install -y debootstrap; }) \
            || die "cannot install debootstrap with apt-get"
    fi
    if [ -d "$tmp" ]; then
        unmount_all_under "$tmp"
        rm -rf "$tmp"
    fi
    mkdir -p "$CACHE"
    debootstrap --variant=minbase "$SUITE" "$tmp" "$mirror" >"$CACHE/debootstrap.log" 2>&1 \
        || die "debootstrap $SUITE from $mirror failed (log: $CACHE/debootstrap.log)"
    # shellcheck disable=SC2086
    chroot_apt_install "$tmp" "$CACHE/chroot-apt.log" $APT_PACKAGES
    umount "$tmp/proc"
    MOUNTS=()
    if [ -d "$ROOT" ]; then
        unmount_all_under "$ROOT"
        rm -rf "$ROOT"
    fi
    mv "$tmp" "$ROOT"
    echo "$CHROOT_RECIPE" >"$ROOT/.relray-chroot"
    ensure_display_packages
    say "chroot ready: $(chroot "$ROOT" blender --version 2>/dev/null | head -1)"
}

install_wheels() {
    # The same versions as .venv has, as cp313 wheels (none of these is in Debian trixie
    # at a version we pin).  pip installs for the chroot's Python from outside it.
    local pins="" p v packages
    packages=$("$PYBIN" -c 'import sys; from relray.relblend.packaging import WHEEL_PACKAGES
print(" ".join(p for p in WHEEL_PACKAGES if p not in sys.argv[1:]))' $DEBIAN_PROVIDED) \
        || die "could not read WHEEL_PACKAGES from relblend/packaging.py"
    for p in $packages; do
        v=$("$PYBIN" -m pip show "$p" 2>/dev/null | awk '/^Version:/ {print $2}')
        [ -n "$v" ] || die "$p is not installed in .venv (run 'make venv')"
        pins="$pins $p==$v"
    done
    local target="$ROOT/opt/relray-py313" stamp="$ROOT/opt/relray-py313/.pins"
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$pins" ]; then
        say "cp313 wheels cached:$pins"
        return
    fi
    say "installing cp313 wheels for the chroot:$pins"
    rm -rf "$target"
    # shellcheck disable=SC2086
    "$PYBIN" -m pip install --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
        --python-version 3.13 --implementation cp --abi cp313 \
        --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
        --platform manylinux2014_x86_64 --target "$target" $pins \
        || die "pip could not get cp313 manylinux wheels for:$pins (see above)"
    echo "$pins" >"$stamp"
}

run_tests() {
    local zipdir="$ROOT/opt/relray-test" user="$ROOT/tmp/relray-blender-user"
    mkdir -p "$zipdir"
    say "building the test extension zip with the bpy module"
    "$PYBIN" "$REPO/relblend/packaging.py" build-test-zip "$zipdir/relray-test.zip" \
        || die "building the extension zip failed"
    rm -rf "$user" && mkdir -p "$user"
    mount_bind "$REPO" "$ROOT/opt/relray-src/relray" ro
    mount_proc "$ROOT"
    mkdir -p "$ROOT/tmp"
    local expr status="$ROOT/tmp/relray-pytest-status"
    rm -f "$status"
    # Blender's own exit code is not the verdict: a render that reports an error (the tests
    # of a bad β do that on purpose) makes `blender -b` exit 1 on its own. The verdict is
    # pytest's exit code, written to a file; --python-exit-code 1 still catches a script
    # that dies before writing it.
    expr=$(cat <<'EOF_EXPR'
import os, sys
sys.dont_write_bytecode = True
sys.path[:0] = ["/opt/relray-py313", "/opt/relray-src/relray/tests/blender"]
import pytest
args = ["/opt/relray-src/relray/tests/blender", "-p", "no:cacheprovider", "-q", "-rA"]
args += [a for a in os.environ.get("RELRAY_PYTEST_ARGS", "").split() if a]
rc = int(pytest.main(args))
with open("/tmp/relray-pytest-status", "w") as f:
    f.write(str(rc))
if rc != 0:
    raise RuntimeError(f"pytest under the real blender binary failed (exit code {rc})")
EOF_EXPR
)
    say "running tests/blender under $(chroot "$ROOT" blender --version 2>/dev/null | head -1)"
    local t0=$SECONDS blender_rc=0
    chroot "$ROOT" /usr/bin/env -i HOME=/root PATH=/usr/local/bin:/usr/bin:/bin LANG=C.UTF-8 \
        RELRAY_BLENDER_HOST=blender \
        RELRAY_TEST_ZIP=/opt/relray-test/relray-test.zip \
        RELRAY_PYTEST_ARGS="${*:-}" \
        RELRAY_PICTURES_DIR=/tmp/relray-pictures \
        BLENDER_USER_RESOURCES=/tmp/relray-blender-user \
        NUMBA_CACHE_DIR=/root/.cache/relray-numba \
        OPENBLAS_NUM_THREADS=1 \
        blender -b --factory-startup --python-exit-code 1 --python-expr "$expr" \
        || blender_rc=$?
    [ -f "$status" ] || fail "blender exited with code $blender_rc before pytest finished (output above)"
    [ "$(cat "$status")" = 0 ] || fail "tests/blender failed under the real blender binary: pytest exit code $(cat "$status") (output above)"
    say "passed under the real blender binary in $((SECONDS - t0)) s"
}

what="${1:-all}"
shift || true
case "$what" in
    setup) build_chroot; install_wheels ;;
    run) run_tests "$@" ;;
    all) build_chroot; install_wheels; run_tests "$@" ;;
    *) die "usage: $0 [setup|run|all] [pytest args]" ;;
esac
