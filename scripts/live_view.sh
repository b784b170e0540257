#!/usr/bin/env bash
# Sourced by the demos. start_live_view LOG_FILE [LAYOUT] starts the Foxglove live bridge
# (live_view) on this shell's DDS domain and prints the URL to open in Foxglove; stop_live_view
# ends it, and stop_demo ends it and the processes a demo put in DEMO_PIDS (SIGINT, then a
# wait). DEMO_LIVE_VIEW=0 leaves the bridge out; DEMO_LIVE_VIEW_PORT picks its port (default
# 8765; 0: any free one); LIVE_VIEW_TAG is the lines' prefix. A bridge that cannot start (the
# port taken) is said in one line and the demo goes on without it.
LIVE_VIEW_PID=""
DEMO_PIDS=()

start_live_view() {
  local log="$1" layout="${2:-}" tag="${LIVE_VIEW_TAG:-demo}"
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
    echo "[$tag] live view: in Foxglove, Open connection > Foxglove WebSocket > $url${layout:+ (layout: $layout)}"
  else
    echo "[$tag] live view not started: $(grep -m1 -E 'FATAL|ERROR|cannot' "$log" || echo "see $log")"
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

stop_demo() {
  stop_live_view
  local pid
  for pid in "${DEMO_PIDS[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  for pid in "${DEMO_PIDS[@]}"; do wait "$pid" 2>/dev/null || true; done
}
