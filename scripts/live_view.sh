#!/usr/bin/env bash
# Sourced by the demos: start_live_view LOG_FILE [LAYOUT] starts the Foxglove live bridge
# (live_view) on this shell's DDS domain and prints the URL to open in Foxglove; the demo
# ends it with stop_live_view. DEMO_LIVE_VIEW=0 leaves it out; DEMO_LIVE_VIEW_PORT picks the
# port (default 8765; 0: any free one). A bridge that cannot start (the port taken) is said
# in one line and the demo goes on without it.
LIVE_VIEW_PID=""

start_live_view() {
  local log="$1" layout="${2:-}"
  [ "${DEMO_LIVE_VIEW:-1}" != 0 ] || return 0
  live_view --ros-args -p port:="${DEMO_LIVE_VIEW_PORT:-8765}" -p use_sim_time:=true \
    > "$log" 2>&1 &
  LIVE_VIEW_PID=$!
  local url=""
  for _ in $(seq 100); do
    url="$(sed -n 's/.*Foxglove WebSocket protocol on \(ws:[^ ]*\).*/\1/p' "$log" | head -1)"
    [ -n "$url" ] && break
    kill -0 "$LIVE_VIEW_PID" 2>/dev/null || break
    sleep 0.1
  done
  if [ -n "$url" ]; then
    echo "[${LIVE_VIEW_TAG:-demo}] live view: in Foxglove, Open connection > Foxglove WebSocket > $url${layout:+ (layout: $layout)}"
  else
    echo "[${LIVE_VIEW_TAG:-demo}] live view not started: $(grep -m1 -E 'FATAL|ERROR|cannot' "$log" || echo "see $log")"
    LIVE_VIEW_PID=""
  fi
}

stop_live_view() {
  if [ -n "$LIVE_VIEW_PID" ]; then
    kill -INT "$LIVE_VIEW_PID" 2>/dev/null || true
    wait "$LIVE_VIEW_PID" 2>/dev/null || true
    LIVE_VIEW_PID=""
  fi
}
