"""Whether a GGUI window can open here: a display, the Vulkan loader and a Vulkan driver;
each failure is a DisplayError that names what is missing and how to get it."""
import ctypes
import ctypes.util
import glob
import os
import sys


class DisplayError(Exception):
    """No window can be opened here; the message says what is missing and how to get it."""


def check_display():
    """Raise DisplayError unless a GGUI window can open: a display, the Vulkan loader and
    at least one Vulkan driver. GLFW ends the process when it finds no display, so this is
    checked before Taichi is asked."""
    if sys.platform.startswith("linux"):
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise DisplayError("no display (DISPLAY is not set): run it on a desktop, over "
                               "ssh -X, or under a virtual one: xvfb-run -a tcloth view ... "
                               "(Debian/Ubuntu: apt-get install xvfb)")
        if os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
            name = ctypes.util.find_library("X11")
            xlib = ctypes.CDLL(name) if name else None
            if xlib is not None:
                xlib.XOpenDisplay.restype = ctypes.c_void_p
                if not xlib.XOpenDisplay(None):
                    raise DisplayError(f"cannot open display {os.environ['DISPLAY']!r}: is "
                                       "the X server running and reachable?")
    check_vulkan()


def check_vulkan():
    """Raise DisplayError unless the Vulkan loader and a Vulkan driver are installed."""
    if sys.platform.startswith("linux"):
        if ctypes.util.find_library("vulkan") is None:
            raise DisplayError("no Vulkan loader (libvulkan.so.1): apt-get install libvulkan1 "
                               "mesa-vulkan-drivers (a software driver) or your GPU's driver")
        listed = os.environ.get("VK_DRIVER_FILES") or os.environ.get("VK_ICD_FILENAMES")
        if listed:      # the loader reads only these
            icds = [p for p in listed.split(os.pathsep) if os.path.isfile(p)]
        else:
            icds = [p for d in ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d",
                                "/usr/local/share/vulkan/icd.d")
                    for p in glob.glob(os.path.join(d, "*.json"))]
        if not icds:
            raise DisplayError("no Vulkan driver: apt-get install mesa-vulkan-drivers (lavapipe, "
                               "a software driver) or your GPU's Vulkan driver")
