#!/usr/bin/env bash
# Sourced by docker/build.sh and docker/test.sh: the container engine and its arguments.
#   CONTAINER_ENGINE  podman or docker (default: podman where it is installed, else docker)
#   IMAGE             the image's name (default robot-sim:latest)
ENGINE="${CONTAINER_ENGINE:-$(command -v podman >/dev/null && echo podman || echo docker)}"
IMAGE="${IMAGE:-robot-sim:latest}"
command -v "$ENGINE" >/dev/null || { echo "[container] error: no $ENGINE: install podman or docker" >&2; exit 1; }
# podman asks the kernel for its own default limits (1048576 open files, more processes than a
# host may allow); without CAP_SYS_RESOURCE (some VMs and sandboxes) runc then fails with
# "error setting rlimit type 7" (or 6). Give it limits within this shell's own: the open files'
# hard limit, and processes up to the 32768 that podman keeps for itself.
LIMITS=()
if [ "$(basename "$ENGINE")" = podman ]; then
  nofile="$(ulimit -Hn)"; nproc="$(ulimit -Hu)"
  [ "$nofile" = unlimited ] && nofile=1048576
  if [ "$nproc" = unlimited ] || [ "$nproc" -gt 32768 ]; then nproc=32768; fi
  LIMITS=(--ulimit "nofile=$nofile:$nofile" --ulimit "nproc=$nproc:$nproc")
fi
