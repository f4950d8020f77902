#!/bin/bash
# Runs CMD... against a fake hidraw device (haptic's copy of shared/tools/fake-hidraw, extended
# with a HID PID force-feedback device). Needs root, unshare, python3-fusepy and libfuse2.
# Everything happens in a private mount namespace: /sys and /dev of the host are untouched.
#   usage: FAKE_HID_KIND=spacemouse|pid run.sh CMD [ARGS...]
# Exits 77, saying why, where it cannot run (not root, no /dev/fuse, fusepy or unshare missing).
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
if [ -z "${IN_FAKE_NS:-}" ]; then
  # Exit 77 (skipped) with the reason when the fake cannot run here.
  why=""
  [ "$(id -u)" = 0 ] || why="not root"
  [ -e /dev/fuse ] || why="no /dev/fuse"
  /usr/bin/python3 -c "import fusepy" 2>/dev/null || why="python3-fusepy missing"
  command -v unshare >/dev/null || why="unshare missing"
  if [ -n "$why" ]; then echo "fake HID unavailable: $why"; exit 77; fi
  exec env IN_FAKE_NS=1 unshare --mount --propagation private "$0" "$@"
fi
KIND=${FAKE_HID_KIND:-spacemouse}
case "$KIND" in
  spacemouse) VID=256F; PID=C635; NAME="Fake 3Dconnexion SpaceMouse";;
  pid)        VID=1234; PID=F00D; NAME="Fake HID PID joystick";;
  *) echo "unknown FAKE_HID_KIND $KIND"; exit 2;;
esac
W=$(mktemp -d /tmp/fakehid.XXXXXX)
mkdir -p "$W/mnt"
/usr/bin/python3 "$HERE/fake_hidraw_fuse.py" "$W/mnt" "$W/device.log" "$W/report_descriptor" "$KIND" &
FUSE_PID=$!
for i in $(seq 50); do [ -e "$W/mnt/hidraw0" ] && break; sleep 0.1; done
[ -e "$W/mnt/hidraw0" ] || { echo "FUSE mount failed"; exit 1; }
mount -t tmpfs fakesys /sys/class/hidraw
R=/sys/class/hidraw/.fake
D=$R/devices/0003:$VID:$PID.0001
mkdir -p $R/class/hid $R/class/hidraw $D/hidraw/hidraw0
printf 'DRIVER=hid-generic\nHID_ID=0003:0000%s:0000%s\nHID_NAME=%s\nHID_PHYS=fake-0/input0\nHID_UNIQ=FAKE0001\n' "$VID" "$PID" "$NAME" > $D/uevent
ln -s ../../class/hid $D/subsystem
cp "$W/report_descriptor" $D/report_descriptor
printf "MAJOR=0\nMINOR=0\nDEVNAME=..$W/mnt/hidraw0\n" > $D/hidraw/hidraw0/uevent
ln -s ../../../../class/hidraw $D/hidraw/hidraw0/subsystem
ln -s ../.. $D/hidraw/hidraw0/device
ln -s .fake/devices/0003:$VID:$PID.0001/hidraw/hidraw0 /sys/class/hidraw/hidraw0
mount -t tmpfs fakechar /sys/dev/char
ln -s /sys/class/hidraw/hidraw0 /sys/dev/char/0:0
set +e
"$@"
rc=$?
echo "--- device log:"; cat "$W/device.log"
umount "$W/mnt"; wait $FUSE_PID 2>/dev/null
rm -rf "$W"
exit $rc
