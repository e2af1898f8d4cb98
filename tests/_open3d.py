"""Import Open3D (a test-only reference) on machines without the system libusb.

Open3D's wheel links against ``libusb-1.0.so.0``, which slim machines lack; the
``libusb-package`` wheel ships that library, and loading it first satisfies the link.
"""

import ctypes
import importlib


def import_open3d():
    """Return the ``open3d`` module, preloading libusb from ``libusb-package`` if needed."""
    try:
        return importlib.import_module("open3d")
    except ImportError as err:
        if "libusb" not in str(err):
            raise
    import libusb_package

    ctypes.CDLL(str(libusb_package.get_library_path()), mode=ctypes.RTLD_GLOBAL)
    return importlib.import_module("open3d")
