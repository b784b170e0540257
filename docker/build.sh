#!/usr/bin/env bash
# make container: build the image of docker/Dockerfile with podman or docker.
#   BASE      the base image (default the Dockerfile's, Debian 12). Where it is neither present
#             nor pullable (no registry) and this is a Debian host with debootstrap, it is made
#             here (docker/base_image.sh).
#   CA_CERT   a PEM file of CA certificates the build trusts (a network that re-signs TLS);
#             default: the CAs this host added to its own store (/usr/local/share/ca-certificates);
#             CA_CERT=none: none.
# and CONTAINER_ENGINE, IMAGE (docker/engine.sh).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=docker/engine.sh
source "$ROOT/docker/engine.sh"
log() { printf '[container] %s\n' "$*"; }
die() { printf '[container] error: %s\n' "$*" >&2; exit 1; }

BASE="${BASE:-$(sed -n 's/^ARG BASE=//p' "$ROOT/docker/Dockerfile")}"
if ! "$ENGINE" image inspect "$BASE" >/dev/null 2>&1; then
  log "base image $BASE: not here, pulling it"
  if ! "$ENGINE" pull "$BASE" >/dev/null 2>&1; then
    case "$BASE" in
      *debian:*) command -v debootstrap >/dev/null || die "cannot pull $BASE and no debootstrap to make it"
                 suite="${BASE##*:}"; suite="${suite%-slim}"
                 log "cannot pull it: making it with debootstrap ($suite)"
                 CONTAINER_ENGINE="$ENGINE" bash "$ROOT/docker/base_image.sh" "$BASE" "$suite" ;;
      *) die "cannot pull $BASE (make a Debian base with docker/base_image.sh, or set BASE)" ;;
    esac
  fi
fi

certs=""
case "${CA_CERT:-}" in
  none) ;;
  "") for f in /usr/local/share/ca-certificates/*.crt; do
        [ -f "$f" ] && certs+="$(cat "$f")"$'\n'
      done
      [ -n "$certs" ] && log "handing the build this host's added CAs (/usr/local/share/ca-certificates; CA_CERT=none: none)" ;;
  *) [ -f "$CA_CERT" ] || die "CA_CERT=$CA_CERT: no such file"
     certs="$(cat "$CA_CERT")" ;;
esac

version="unknown"
if git -C "$ROOT" rev-parse --short=12 HEAD >/dev/null 2>&1; then
  version="$(git -C "$ROOT" rev-parse --short=12 HEAD)"
  # dirty as the results count it (trial_record.result.code_version): code outside docs/
  [ -z "$(git -C "$ROOT" status --porcelain --untracked-files=no -- . ':(exclude)docs' \
    ':(exclude)*.md')" ] || version+="-dirty"
fi

log "building $IMAGE from $BASE with $ENGINE (code $version)"
start=$SECONDS
"$ENGINE" build "${LIMITS[@]}" -f "$ROOT/docker/Dockerfile" -t "$IMAGE" \
  --build-arg "BASE=$BASE" --build-arg "CODE_VERSION=$version" \
  ${certs:+--build-arg "EXTRA_CA_CERT=$certs"} "$ROOT"
size="$("$ENGINE" image inspect --format '{{.Size}}' "$IMAGE" | awk '{printf "%.2f GB", $1/1e9}')"
log "built $IMAGE in $((SECONDS - start)) s, $size; run the demo with: $ENGINE run --rm ${LIMITS[*]} $IMAGE"
