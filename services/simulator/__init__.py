"""The MuJoCo simulator service.

Importing the package picks the offscreen GL backend before MuJoCo is imported (MuJoCo reads
MUJOCO_GL once, at import): EGL when libEGL is present, else OSMesa; an explicit MUJOCO_GL
wins. When no GL context can be made at all, the camera falls back to ray casting.
"""

from __future__ import annotations

import ctypes.util
import os

if "MUJOCO_GL" not in os.environ:
    if ctypes.util.find_library("EGL"):
        os.environ["MUJOCO_GL"] = "egl"
    elif ctypes.util.find_library("OSMesa"):
        os.environ["MUJOCO_GL"] = "osmesa"
