"""Which Vulkan devices this machine has, asked of the Vulkan loader through ctypes (Taichi
does not say which device it runs on). Used to warn when ``arch="vulkan"`` or
``arch="gpu"`` lands on a software driver (Mesa's lavapipe, "llvmpipe"), which runs on the
CPU far slower than ``arch="cpu"``."""
import ctypes
import ctypes.util

# VkPhysicalDeviceType
DEVICE_TYPES = {0: "other", 1: "integrated GPU", 2: "discrete GPU", 3: "virtual GPU",
                4: "CPU"}
_PROPERTIES_BYTES = 1024        # VkPhysicalDeviceProperties is 824 bytes on 64-bit Linux


class _InstanceCreateInfo(ctypes.Structure):
    _fields_ = [("sType", ctypes.c_int), ("pNext", ctypes.c_void_p),
                ("flags", ctypes.c_uint32), ("pApplicationInfo", ctypes.c_void_p),
                ("enabledLayerCount", ctypes.c_uint32),
                ("ppEnabledLayerNames", ctypes.c_void_p),
                ("enabledExtensionCount", ctypes.c_uint32),
                ("ppEnabledExtensionNames", ctypes.c_void_p)]


def devices():
    """[(name, type)] of the Vulkan physical devices, type one of DEVICE_TYPES' values;
    [] when there is no loader or no driver."""
    path = ctypes.util.find_library("vulkan") or "libvulkan.so.1"
    try:
        vk = ctypes.CDLL(path)
    except OSError:
        return []
    info = _InstanceCreateInfo(sType=1)        # VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO
    instance = ctypes.c_void_p()
    if vk.vkCreateInstance(ctypes.byref(info), None, ctypes.byref(instance)) != 0:
        return []
    found = []
    try:
        count = ctypes.c_uint32()
        vk.vkEnumeratePhysicalDevices(instance, ctypes.byref(count), None)
        handles = (ctypes.c_void_p * count.value)()
        vk.vkEnumeratePhysicalDevices(instance, ctypes.byref(count), handles)
        for handle in handles[:count.value]:
            raw = ctypes.create_string_buffer(_PROPERTIES_BYTES)
            vk.vkGetPhysicalDeviceProperties(ctypes.c_void_p(handle), raw)
            # apiVersion, driverVersion, vendorID, deviceID, deviceType, deviceName[256]
            kind = int.from_bytes(raw.raw[16:20], "little")
            name = raw.raw[20:276].split(b"\0", 1)[0].decode(errors="replace")
            found.append((name, DEVICE_TYPES.get(kind, "other")))
    finally:
        vk.vkDestroyInstance(instance, None)
    return found
