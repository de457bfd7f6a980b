"""URDF edits for pybullet: fold every fixed joint into its parent link keeping mass properties exact
(:func:`flatten_fixed_joints`), and replace a foot's collision shapes with a flat sole box
(:func:`replace_foot_collisions_with_sole_boxes`).

pybullet's own ``URDF_MERGE_FIXED_LINKS`` loses the merged link's inertial offset (the CoM of e.g. a
foot with a sole frame ends at the link origin), which makes a standing robot slip. Here the inertias
are combined with pinocchio's spatial inertia algebra, and visual/collision shapes and child joints
are re-attached to the host link with composed origins. The result has one link per movable joint
(plus the root), which is also what makes pybullet fast.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin


def _origin(elem: ET.Element | None) -> pin.SE3:
    """SE3 of an ``<origin xyz rpy>`` child of ``elem`` (identity if absent)."""
    o = None if elem is None else elem.find("origin")
    if o is None:
        return pin.SE3.Identity()
    xyz = np.array([float(v) for v in o.get("xyz", "0 0 0").split()])
    rpy = [float(v) for v in o.get("rpy", "0 0 0").split()]
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), xyz)


def _fmt(values: np.ndarray) -> str:
    return " ".join(f"{float(v):.12g}" for v in values)


def _set_origin(elem: ET.Element, T: pin.SE3) -> None:
    o = elem.find("origin")
    if o is None:
        o = ET.Element("origin")
        elem.insert(0, o)
    o.set("xyz", _fmt(T.translation))
    o.set("rpy", _fmt(pin.rpy.matrixToRpy(T.rotation)))


def _inertia(link: ET.Element) -> pin.Inertia:
    """Spatial inertia of a link in its own frame (zero if no ``<inertial>``)."""
    inertial = link.find("inertial")
    if inertial is None:
        return pin.Inertia.Zero()
    mass_el = inertial.find("mass")
    mass = float(mass_el.get("value", "0")) if mass_el is not None else 0.0
    i = inertial.find("inertia")
    get = (lambda k: float(i.get(k, "0"))) if i is not None else (lambda k: 0.0)
    I_c = np.array(
        [
            [get("ixx"), get("ixy"), get("ixz")],
            [get("ixy"), get("iyy"), get("iyz")],
            [get("ixz"), get("iyz"), get("izz")],
        ]
    )
    T = _origin(inertial)
    # Inertia at the CoM in the inertial frame axes -> expressed in the link frame.
    return pin.Inertia(mass, np.zeros(3), I_c).se3Action(T) if mass > 0.0 else pin.Inertia.Zero()


def _write_inertial(link: ET.Element, inertia: pin.Inertia) -> None:
    for old in link.findall("inertial"):
        link.remove(old)
    inertial = ET.Element("inertial")
    origin = ET.SubElement(inertial, "origin")
    origin.set("xyz", _fmt(inertia.lever))
    origin.set("rpy", "0 0 0")
    ET.SubElement(inertial, "mass").set("value", f"{inertia.mass:.12g}")
    Ic = inertia.inertia
    ET.SubElement(inertial, "inertia").attrib.update(
        {
            "ixx": f"{Ic[0, 0]:.12g}",
            "ixy": f"{Ic[0, 1]:.12g}",
            "ixz": f"{Ic[0, 2]:.12g}",
            "iyy": f"{Ic[1, 1]:.12g}",
            "iyz": f"{Ic[1, 2]:.12g}",
            "izz": f"{Ic[2, 2]:.12g}",
        }
    )
    link.insert(0, inertial)


def flatten_fixed_joints(urdf_text: str) -> tuple[str, dict[str, str]]:
    """Return (URDF text without fixed joints, map merged link name -> host link name)."""
    root = ET.fromstring(urdf_text)
    links = {link.get("name"): link for link in root.findall("link")}
    joints = root.findall("joint")
    parent_joint = {j.find("child").get("link"): j for j in joints}

    def host_of(name: str) -> tuple[str, pin.SE3]:
        """Nearest ancestor reached through fixed joints only, and T_host_link."""
        T = pin.SE3.Identity()
        while name in parent_joint and parent_joint[name].get("type") == "fixed":
            j = parent_joint[name]
            T = _origin(j) * T
            name = j.find("parent").get("link")
        return name, T

    hosts: dict[str, tuple[str, pin.SE3]] = {name: host_of(name) for name in links}
    inertia = {name: _inertia(link) for name, link in links.items()}
    merged: dict[str, str] = {}
    for name, (host, T_host_link) in hosts.items():
        if host == name:
            continue
        merged[name] = host
        inertia[host] = inertia[host] + inertia[name].se3Action(T_host_link)
        for tag in ("visual", "collision"):
            for geom in links[name].findall(tag):
                _set_origin(geom, T_host_link * _origin(geom))
                links[host].append(geom)
    for name, link in links.items():
        if name not in merged and inertia[name].mass > 0.0:
            _write_inertial(link, inertia[name])
    for j in joints:
        if j.get("type") == "fixed":
            root.remove(j)
            continue
        parent = j.find("parent").get("link")
        if parent in merged:
            host, T_host_parent = hosts[parent]
            j.find("parent").set("link", host)
            _set_origin(j, T_host_parent * _origin(j))
    for name in merged:
        root.remove(links[name])
    return ET.tostring(root, encoding="unicode"), merged


def replace_foot_collisions_with_sole_boxes(
    urdf_text: str, sole_links: tuple[str, ...], size_m: tuple[float, float], thickness_m: float
) -> tuple[str, dict[str, str]]:
    """Return (URDF text, map sole link -> foot link) where the collision shapes of every foot carrying
    one of ``sole_links`` are replaced with one box.

    The foot link of a sole is its nearest ancestor reached through fixed joints only, or the sole link
    itself. The box is ``size_m`` = (length along the sole x, width along y) [m] and ``thickness_m`` [m]
    high, its bottom face centred on the sole frame: a flat sole exactly at the sole frame (CONVENTIONS
    §5: "soles must be exactly flat"). Collision shapes of the links between the sole and the foot
    (fixed-joint children) are removed as well. Visuals and inertials are untouched.
    """
    if thickness_m <= 0.0 or min(size_m) <= 0.0:
        raise ValueError(f"sole box size {size_m} x {thickness_m} m must be positive")
    root = ET.fromstring(urdf_text)
    links = {link.get("name"): link for link in root.findall("link")}
    parent_joint = {j.find("child").get("link"): j for j in root.findall("joint")}
    feet: dict[str, str] = {}
    for sole in sole_links:
        if sole not in links:
            raise ValueError(f"sole link {sole!r} is not in the URDF")
        name, T_foot_sole, chain = sole, pin.SE3.Identity(), [sole]
        while name in parent_joint and parent_joint[name].get("type") == "fixed":
            j = parent_joint[name]
            T_foot_sole = _origin(j) * T_foot_sole
            name = j.find("parent").get("link")
            chain.append(name)
        for link_name in chain:
            for geom in links[link_name].findall("collision"):
                links[link_name].remove(geom)
        collision = ET.SubElement(links[name], "collision")
        collision.set("name", f"{sole}_box")
        lift = pin.SE3(np.eye(3), np.array([0.0, 0.0, thickness_m / 2.0]))
        _set_origin(collision, T_foot_sole * lift)
        geometry = ET.SubElement(collision, "geometry")
        ET.SubElement(geometry, "box").set("size", _fmt(np.array([size_m[0], size_m[1], thickness_m])))
        feet[sole] = name
    return ET.tostring(root, encoding="unicode"), feet
