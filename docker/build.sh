#!/usr/bin/env bash
# Build the robot image from docker/Dockerfile with buildah, run a smoke test inside it
# (a headless recorded run, the recording read back), and report the image's size.
#
#   docker/build.sh [--arch amd64|arm64] [--tag NAME] [--sessions DIR] [--no-smoke]
#
# --arch    the image's architecture (default: this machine's); another one runs under
#           QEMU's user-mode emulation (Debian's qemu-user-static, installed when missing)
# --tag     the image's name (default ucat-console:ARCH)
# --sessions where the smoke run's recording goes on this machine (default: a temporary
#           folder, removed afterwards)
#
# The base is the Dockerfile's FROM (python:3.11-slim-bookworm) when its registry answers.
# Where no container registry is reachable, it is a Debian bookworm root made by debootstrap
# from the Debian mirror, with Debian's Python 3.11 in a virtual environment first on PATH
# (as the python image's /usr/local): the root is made once and kept, as a tar file in
# $UCAT_IMAGE_CACHE (default /var/cache/ucat-console) and as the image
# localhost/ucat-base:bookworm-ARCH in buildah's storage (/var/lib/containers), so later
# builds start from it in seconds. Needs root (buildah, debootstrap, chroot) and the Debian
# and PyPI mirrors. docs/robot.md says how to use it for the robot.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
CACHE="${UCAT_IMAGE_CACHE:-/var/cache/ucat-console}"
FROM_IMAGE="python:3.11-slim-bookworm"
MIRROR="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"

host_arch="$(dpkg --print-architecture)"
arch="$host_arch"
tag=""
sessions=""
smoke=1
while [ $# -gt 0 ]; do
  case "$1" in
    --arch) arch="$2"; shift 2 ;;
    --tag) tag="$2"; shift 2 ;;
    --sessions) sessions="$2"; shift 2 ;;
    --no-smoke) smoke=0; shift ;;
    -h|--help) sed -n '2,21p' "$0"; exit 0 ;;
    *) echo "docker/build.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
case "$arch" in
  amd64|arm64) ;;
  *) echo "docker/build.sh: --arch: expected amd64 or arm64, got $arch" >&2; exit 2 ;;
esac
tag="${tag:-ucat-console:$arch}"
if [ "$(id -u)" != 0 ]; then
  echo "docker/build.sh: needs root (buildah with chroot isolation, debootstrap)" >&2
  exit 1
fi

log() { echo "[$(date +%H:%M:%S)] $*"; }
t_start=$(date +%s)

need=()
command -v buildah >/dev/null || need+=(buildah)
command -v debootstrap >/dev/null || need+=(debootstrap)
if [ "$arch" != "$host_arch" ] && ! command -v "qemu-${arch/arm64/aarch64}-static" >/dev/null; then
  need+=(qemu-user-static binfmt-support)
fi
if [ ${#need[@]} -gt 0 ]; then
  log "installing ${need[*]}"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}"
fi
if [ "$arch" != "$host_arch" ]; then
  # QEMU runs the other architecture's programs through binfmt_misc
  [ -e /proc/sys/fs/binfmt_misc/status ] || mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
  update-binfmts --enable "qemu-${arch/arm64/aarch64}" 2>/dev/null || true
  if [ ! -e "/proc/sys/fs/binfmt_misc/qemu-${arch/arm64/aarch64}" ]; then
    echo "docker/build.sh: QEMU's binfmt handler for $arch is not registered" >&2
    exit 1
  fi
fi

# ------------------------------------------------------------------ the base
base_image="localhost/ucat-base:bookworm-$arch"
from_args=()
if buildah pull -q --arch "$arch" "$FROM_IMAGE" >/dev/null 2>&1; then
  log "base: $FROM_IMAGE from its registry"
else
  log "base: no registry answers for $FROM_IMAGE; a debootstrap root instead ($base_image)"
  if ! buildah inspect --type image "$base_image" >/dev/null 2>&1; then
    tarball="$CACHE/bookworm-python-$arch.tar"
    if [ ! -f "$tarball" ]; then
      mkdir -p "$CACHE"
      rootfs="$(mktemp -d "$CACHE/rootfs-$arch.XXXXXX")"
      log "debootstrap bookworm ($arch) into $rootfs"
      debootstrap --arch "$arch" --variant=minbase --include=python3,python3-venv,ca-certificates \
        bookworm "$rootfs" "$MIRROR"
      # the python image's `python` and `pip` first on PATH: a virtual environment of
      # Debian's python3 (3.11), outside Debian's own packages
      chroot "$rootfs" /usr/bin/python3 -m venv /opt/python
      rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/*
      tar -C "$rootfs" -cf "$tarball.part" .
      mv "$tarball.part" "$tarball"
      rm -rf "$rootfs"
    fi
    log "importing $tarball as $base_image"
    ctr="$(buildah from --arch "$arch" scratch)"
    buildah add "$ctr" "$tarball" / >/dev/null
    buildah config --arch "$arch" --os linux --env LANG=C.UTF-8 \
      --env PATH=/opt/python/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
      --cmd python3 "$ctr"
    buildah commit -q "$ctr" "$base_image" >/dev/null
    buildah rm "$ctr" >/dev/null
  fi
  from_args=(--from "$base_image")
fi

# ------------------------------------------------------------------ the image
# pip inside the build trusts the certificate authorities this machine's pip trusts
# (PIP_CERT, else the system's bundle: a proxy's own authority may be among them), through
# files mounted for the build only, never part of the image
build_args=()
host_ca="${PIP_CERT:-/etc/ssl/certs/ca-certificates.crt}"
if [ -f "$host_ca" ]; then
  pipconf="$(mktemp)"
  printf '[global]\ncert = /etc/ssl/certs/build-host-ca.crt\n' > "$pipconf"
  build_args+=(-v "$host_ca:/etc/ssl/certs/build-host-ca.crt:ro" -v "$pipconf:/etc/pip.conf:ro")
fi
# the image's version label: the package's (pyproject.toml)
version="$(sed -n 's/^version *= *"\(.*\)"/\1/p' "$ROOT/pyproject.toml" | head -n1)"
build_args+=(--build-arg "UCAT_CONSOLE_VERSION=$version")
log "building $tag (ucat-console $version) from docker/Dockerfile"
old_id="$(buildah images -q "$tag" 2>/dev/null || true)"
t_build=$(date +%s)
buildah bud --isolation chroot --arch "$arch" "${from_args[@]}" "${build_args[@]}" \
  -f "$ROOT/docker/Dockerfile" --ignorefile "$ROOT/docker/Dockerfile.dockerignore" \
  -t "$tag" "$ROOT"
[ -z "${pipconf:-}" ] || rm -f "$pipconf"
# the image this build replaces under the same name is removed, not left dangling
if [ -n "$old_id" ] && [ "$old_id" != "$(buildah images -q "$tag")" ]; then
  buildah rmi "$old_id" >/dev/null 2>&1 || true
fi
log "built $tag in $(( $(date +%s) - t_build )) s"

# ------------------------------------------------------------------ the smoke test
if [ "$smoke" = 1 ]; then
  keep="$sessions"
  sessions="${sessions:-$(mktemp -d)}"
  mkdir -p "$sessions"
  inside="$(buildah inspect --type image --format '{{range .OCIv1.Config.Env}}{{println .}}{{end}}' "$tag" \
            | sed -n 's/^UCAT_CONSOLE_SESSIONS=//p')"
  ctr="$(buildah from "$tag")"
  trap 'buildah rm "$ctr" >/dev/null 2>&1 || true' EXIT
  # the image runs as its own user (not root): the recordings folder must be its
  chown "$(buildah run --isolation chroot "$ctr" -- id -u):$(buildah run --isolation chroot "$ctr" -- id -g)" "$sessions"
  log "smoke test as $(buildah run --isolation chroot "$ctr" -- id -un) ($(buildah run --isolation chroot "$ctr" -- id -Gn)):" \
      "ucat-console run --headless --duration 5 --record (recordings: $sessions)"
  buildah run --isolation chroot "$ctr" -- touch /tmp/.smoke-start
  buildah run --isolation chroot -v "$sessions:$inside" "$ctr" -- \
    ucat-console run --headless --duration 5 --record
  # the run loaded every kernel from the cache the build prepared (generic CPU): it wrote none
  written="$(buildah run --isolation chroot "$ctr" -- sh -c \
    'find "$UCAT_CONSOLE_CACHE_DIR" -newer /tmp/.smoke-start -name "*.nbc" | wc -l')"
  log "smoke test: $written compiled-code files written by the run (0: the image's prepared cache served it)"
  # the recording, read back by the image's own reader: 5 s of the robot's state
  buildah run --isolation chroot -v "$sessions:$inside" "$ctr" -- python -c '
import os, sys
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.telemetry import channels as ch
folder = os.environ["UCAT_CONSOLE_SESSIONS"]
parts = sorted(f for f in os.listdir(folder) if f.endswith(".mcap"))
if len(parts) != 1:
    sys.exit(f"smoke test: expected one recording in {folder}, found {parts}")
with SessionReader(os.path.join(folder, parts[0]), folder) as r:
    states = r.message_counts().get(ch.BODY_STATE, 0)
    print(f"smoke test: {parts[0]}: {r.duration:.1f} s, {states} body states")
    if r.duration < 5.0 - 0.05 or states == 0:
        sys.exit("smoke test: the recording is shorter than the run or holds no body state")
'
  buildah rm "$ctr" >/dev/null
  trap - EXIT
  [ -n "$keep" ] || rm -rf "$sessions"
fi

size="$(buildah images --format '{{.Size}}' "$tag" | head -n1)"
log "image $tag ($arch): $size; $(( $(date +%s) - t_start )) s in all"
