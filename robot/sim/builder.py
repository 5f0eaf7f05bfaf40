"""A small MJCF writer: elements, assets held in memory, and mesh/texture registration.

MuJoCo compiles the XML string with the in-memory asset dictionary
(``mujoco.MjModel.from_xml_string(xml, assets)``), so nothing is written to disk.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.sim.meshes import Mesh
from robot.sim.textures import png_bytes

__all__ = ["MjcfBuilder", "fmt", "quat_from_matrix"]


def fmt(values: Iterable[float] | ArrayLike) -> str:
    """Space-separated numbers with enough digits to round-trip float64 geometry."""
    return " ".join(f"{float(v):.12g}" for v in np.asarray(values, dtype=np.float64).ravel())


def quat_from_matrix(R: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix (Shepperd's method), w >= 0."""
    M = np.asarray(R, dtype=np.float64)
    if M.shape != (3, 3):
        raise ValueError(f"R must have shape (3, 3), got {M.shape}")
    tr = np.trace(M)
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2.0
        q = [0.25 * s, (M[2, 1] - M[1, 2]) / s, (M[0, 2] - M[2, 0]) / s, (M[1, 0] - M[0, 1]) / s]
    elif M[0, 0] > M[1, 1] and M[0, 0] > M[2, 2]:
        s = math.sqrt(1.0 + M[0, 0] - M[1, 1] - M[2, 2]) * 2.0
        q = [(M[2, 1] - M[1, 2]) / s, 0.25 * s, (M[0, 1] + M[1, 0]) / s, (M[0, 2] + M[2, 0]) / s]
    elif M[1, 1] > M[2, 2]:
        s = math.sqrt(1.0 + M[1, 1] - M[0, 0] - M[2, 2]) * 2.0
        q = [(M[0, 2] - M[2, 0]) / s, (M[0, 1] + M[1, 0]) / s, 0.25 * s, (M[1, 2] + M[2, 1]) / s]
    else:
        s = math.sqrt(1.0 + M[2, 2] - M[0, 0] - M[1, 1]) * 2.0
        q = [(M[1, 0] - M[0, 1]) / s, (M[0, 2] + M[2, 0]) / s, (M[1, 2] + M[2, 1]) / s, 0.25 * s]
    qa = np.asarray(q)
    qa /= np.linalg.norm(qa)
    return -qa if qa[0] < 0 else qa


class MjcfBuilder:
    """Collects the parts of one MJCF document.

    Attributes
    ----------
    root, asset, worldbody, actuator : xml.etree.ElementTree.Element
        The document's main sections.
    assets : dict of str to bytes
        Files referenced by the XML (PNG textures), passed to MuJoCo with it.
    """

    def __init__(self, model_name: str) -> None:
        self.root = ET.Element("mujoco", model=model_name)
        ET.SubElement(self.root, "compiler", angle="radian", autolimits="true")
        self.option = ET.SubElement(self.root, "option")
        self.visual = ET.SubElement(self.root, "visual")
        self.asset = ET.SubElement(self.root, "asset")
        self.worldbody = ET.SubElement(self.root, "worldbody")
        self.actuator = ET.SubElement(self.root, "actuator")
        self.assets: dict[str, bytes] = {}
        self._names: set[str] = set()

    def _unique(self, kind: str, name: str) -> str:
        key = f"{kind}:{name}"
        if key in self._names:
            raise ValueError(f"{kind} {name!r} is defined twice")
        self._names.add(key)
        return name

    def texture(self, name: str, image: NDArray[np.uint8]) -> str:
        """Register a 2D texture from an RGB image; returns its name."""
        self._unique("texture", name)
        file = f"{name}.png"
        self.assets[file] = png_bytes(image)
        ET.SubElement(self.asset, "texture", name=name, type="2d", file=file)
        return name

    def material(
        self,
        name: str,
        *,
        rgba: ArrayLike = (1.0, 1.0, 1.0, 1.0),
        texture: str | None = None,
        specular: float = 0.3,
        shininess: float = 0.3,
        texrepeat: tuple[float, float] | None = None,
        texuniform: bool = False,
    ) -> str:
        """Register a material; returns its name."""
        self._unique("material", name)
        attrs = {
            "name": name,
            "rgba": fmt(rgba),
            "specular": f"{specular:g}",
            "shininess": f"{shininess:g}",
        }
        if texture is not None:
            attrs["texture"] = texture
        if texrepeat is not None:
            attrs["texrepeat"] = fmt(texrepeat)
        if texuniform:
            attrs["texuniform"] = "true"
        ET.SubElement(self.asset, "material", attrs)
        return name

    def mesh(self, name: str, mesh: Mesh) -> str:
        """Register a triangle mesh with its normals and texture coordinates."""
        self._unique("mesh", name)
        ET.SubElement(
            self.asset,
            "mesh",
            name=name,
            vertex=fmt(mesh.vertices),
            normal=fmt(mesh.normals),
            texcoord=fmt(mesh.uv),
            face=" ".join(str(int(i)) for i in mesh.faces.ravel()),
            inertia="shell",
        )
        return name

    @staticmethod
    def visual_geom(parent: ET.Element, **attrs: str) -> ET.Element:
        """A geom that is drawn but never collides."""
        attrs.setdefault("contype", "0")
        attrs.setdefault("conaffinity", "0")
        return ET.SubElement(parent, "geom", attrs)

    def to_xml(self) -> str:
        """The document as a string."""
        ET.indent(self.root)
        return ET.tostring(self.root, encoding="unicode")
