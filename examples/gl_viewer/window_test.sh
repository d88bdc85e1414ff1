#!/usr/bin/env bash
# The window path of gl_viewer under a virtual X server (run by ctest through xvfb-run): opens
# the window on the generated scene built as a point-octree, and passes when the window's title
# reports a drawn frame (its splat count) within 120 s. GLFW, GLX and Mesa draw it as on a
# desktop; only the input events are not exercised.
set -u
viewer="$1"
"$viewer" --method point-octree --tolerance 2 --size 320x240 &
pid=$!
status=1
for _ in $(seq 240); do
  if title=$(xwininfo -root -tree 2> /dev/null | grep -o '"gl_viewer [^"]*splats[^"]*"'); then
    echo "window title: $title"
    echo "$title" | grep -q ' 0 splats' || status=0
    break
  fi
  kill -0 "$pid" 2> /dev/null || break
  sleep 0.5
done
kill "$pid" 2> /dev/null
wait "$pid" 2> /dev/null
[ "$status" = 0 ] || echo "gl_viewer: no window with a drawn frame" >&2
exit "$status"
