#!/usr/bin/env bash
# Make a Debian base image without a registry: debootstrap a minimal Debian into a folder and
# import it into the container engine under the name the Dockerfile starts from.
#   docker/base_image.sh [IMAGE] [SUITE] [MIRROR]
# defaults: docker.io/library/debian:bookworm-slim, bookworm, http://deb.debian.org/debian.
# Needs root and debootstrap (apt-get install debootstrap). The image is a stand-in for the
# registry's image of that name: a minbase Debian of the same suite, labelled as made here.
set -euo pipefail
IMAGE="${1:-docker.io/library/debian:bookworm-slim}"
SUITE="${2:-bookworm}"
MIRROR="${3:-http://deb.debian.org/debian}"
ENGINE="${CONTAINER_ENGINE:-$(command -v podman >/dev/null && echo podman || echo docker)}"
log() { printf '[base_image] %s\n' "$*"; }
die() { printf '[base_image] error: %s\n' "$*" >&2; exit 1; }

[ "$(id -u)" = 0 ] || die "debootstrap needs root"
command -v debootstrap >/dev/null || die "no debootstrap: apt-get install debootstrap"
root="$(mktemp -d /tmp/robot-sim-base.XXXXXX)"
trap 'rm -rf "$root"' EXIT
log "debootstrap $SUITE from $MIRROR (minbase)"
debootstrap --variant=minbase "$SUITE" "$root/fs" "$MIRROR" > "$root/debootstrap.log" 2>&1 \
  || { tail -20 "$root/debootstrap.log" >&2; die "debootstrap failed"; }
# As the registry's image has them: the suite's updates and security archives, no apt lists.
cat > "$root/fs/etc/apt/sources.list" <<SOURCES
deb $MIRROR $SUITE main
deb $MIRROR $SUITE-updates main
deb ${MIRROR%/debian}/debian-security $SUITE-security main
SOURCES
rm -rf "$root/fs/var/lib/apt/lists/"* "$root/fs/var/cache/apt/"*.bin "$root/fs/tmp/"*
log "importing it as $IMAGE ($ENGINE)"
tar -C "$root/fs" -c . | "$ENGINE" import \
  --change 'CMD ["bash"]' --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
  --change "LABEL org.opencontainers.image.description=debootstrap-$SUITE-minbase" \
  - "$IMAGE" > /dev/null
log "done: $("$ENGINE" image inspect --format '{{.Size}}' "$IMAGE" | awk '{printf "%.0f MB", $1/1e6}')"
