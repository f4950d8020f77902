#!/usr/bin/python3
"""Userspace fake /dev/hidrawN for haptic's HID tests (a kernel without UHID).

Serves one file 'hidraw0' over FUSE, as one of two devices (argv[4]):
  spacemouse: input reports 1 (X Y Z int16) and 2 (Rx Ry Rz int16) streamed at ~100 Hz;
  pid:        a HID PID force-feedback device answering Create New Effect (feature set,
              id 0x0b) and PID Block Load (feature get, id 0x0c: block 7, success).
  * ioctl HIDIOCGRDESCSIZE       -> size of the report descriptor
  * ioctl HIDIOCSFEATURE(len)    -> logged as "feature set: HEX"
  * ioctl HIDIOCGFEATURE(len)    -> answered for id 0x0c, logged as "feature get: HEX"
  * write()                      -> logged as "output report: HEX"
Run: fake_hidraw_fuse.py MOUNTPOINT LOGFILE DESCFILE KIND
"""
import ctypes, errno, stat, struct, sys, threading, time, queue
from fusepy import FUSE, Operations, FuseOSError

SPACEMOUSE = bytes.fromhex(
    "0501 0908 a101"
    "8501 16a2fe 265e01 0930 0931 0932 7510 9503 8102"
    "8502 0933 0934 0935 7510 9503 8102"
    "8503 0509 1901 2902 1500 2501 7501 9502 8102 9506 8101"
    "8504 0508 094b 1500 2501 7501 9501 9102 9507 9101"
    "c0".replace(" ", ""))
PID = bytes.fromhex(
    "0501 0904 a101"                                   # Generic Desktop / Joystick
    "8501 0930 1500 26ff00 7508 950b 9102"             # out 1: Set Effect (11 bytes)
    "8505 0931 9503 9102"                              # out 5: Set Constant Force
    "850a 0932 9503 9102"                              # out 10: Effect Operation
    "850b 0933 9503 b102"                              # feature 11: Create New Effect
    "850c 0934 9504 b102"                              # feature 12: PID Block Load
    "c0".replace(" ", ""))
HIDIOCGRDESCSIZE = 0x80044801
IOC_RW, HID_TYPE = 3, 0x48

def ioc(nr, size):
    return (IOC_RW << 30) | (size << 16) | (HID_TYPE << 8) | nr

class FakeHidraw(Operations):
    def __init__(self, log, kind):
        self.kind = kind
        self.desc = SPACEMOUSE if kind == "spacemouse" else PID
        self.q = queue.Queue()
        self.log = open(log, "a", buffering=1)
        if kind == "spacemouse":
            threading.Thread(target=self.motion, daemon=True).start()

    def motion(self):
        i = 0
        while True:
            i += 1
            self.q.put(struct.pack("<Bhhh", 1, i % 350, -(i % 350), 7))
            self.q.put(struct.pack("<Bhhh", 2, 1, 2, 3))
            time.sleep(0.01)

    def getattr(self, path, fh=None):
        now = time.time()
        if path == "/":
            return dict(st_mode=stat.S_IFDIR | 0o755, st_nlink=2, st_ctime=now, st_mtime=now, st_atime=now)
        if path == "/hidraw0":
            return dict(st_mode=stat.S_IFREG | 0o666, st_nlink=1, st_size=0, st_ctime=now, st_mtime=now, st_atime=now)
        raise FuseOSError(errno.ENOENT)

    def readdir(self, path, fh):
        return [".", "..", "hidraw0"]

    def open(self, path, flags):
        self.log.write(f"open {path}\n")
        return 0

    def read(self, path, size, offset, fh):
        try:
            r = self.q.get(timeout=0.2)
        except queue.Empty:
            return b""
        return r[:size]

    def write(self, path, data, offset, fh):
        self.log.write(f"output report: {data.hex()}\n")
        return len(data)

    def truncate(self, path, length, fh=None):
        return 0

    def ioctl(self, path, cmd, arg, fh, flags, data):
        cmd &= 0xFFFFFFFF
        size = (cmd >> 16) & 0x3FFF
        if cmd == HIDIOCGRDESCSIZE:
            ctypes.memmove(data, struct.pack("<i", len(self.desc)), 4)
            return 0
        if self.kind == "pid" and cmd == ioc(0x06, size):
            self.log.write(f"feature set: {ctypes.string_at(data, size).hex()}\n")
            return size
        if self.kind == "pid" and cmd == ioc(0x07, size):
            asked = ctypes.string_at(data, size)
            self.log.write(f"feature get: {asked[:1].hex()}\n")
            if asked[:1] == b"\x0c":
                reply = bytes([0x0C, 7, 1, 0, 0])[:size]
                ctypes.memmove(data, reply, len(reply))
                return len(reply)
            raise FuseOSError(errno.EINVAL)
        self.log.write(f"ioctl {cmd:#x} refused\n")
        raise FuseOSError(errno.ENOTTY)

if __name__ == "__main__":
    mnt, log, descfile, kind = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
    fake = FakeHidraw(log, kind)
    open(descfile, "wb").write(fake.desc)
    FUSE(fake, mnt, foreground=True, direct_io=True, allow_other=True, nothreads=False)
