# Copyright 2026 umbrella_sim developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The URDF of the umbrella frame, built from the parameters (no ROS imports).

Links and frames (all in the XY plane of the inertial frame; rotations about +Z):

- ``umbrella_base``: the inertial frame XOY, origin at the leaf hinge O, +Y up the axle on which
  the sleeve slides, +X toward the leaf.  The root.
- ``leaf``: origin O, x axis through the link joint O'' (the leaf's floating frame); joint
  ``leaf_hinge`` (revolute about Z from ``umbrella_base``) = alpha1.
- ``link``: origin O'', x axis through the sleeve joint H (the link's floating frame); joint
  ``link_hinge`` (revolute about Z from ``leaf``, at x = l1) = alpha2 - alpha1.
- ``sleeve``: origin H on the axle; joint ``sleeve_slider`` (prismatic along +Y from
  ``umbrella_base``) = y_H.
- ``tip``: the undeformed tip G on the leaf's floating frame (fixed joint ``leaf_tip`` at
  x = l1 + l2 of ``leaf``); ``tip_deflection`` is G's elastic displacement from it, along
  the axes of ``leaf``.

Loop closure: the mechanism is a closed chain (O - O'' - H - axle - O), which URDF cannot
express; the tree above leaves out the pin joint between the link's end (x'' = l3) and the
sleeve.  For the rigid models the joint_states close it to round-off (2.5e-16 m measured),
so robot_state_publisher places ``link``'s end on ``sleeve``.  For the flexible models
alpha1 and alpha2 are the beams' floating frames: the solver pins the *deformed* link's end
to H, and the URDF's rigid end misses the sleeve by the beams' elastic displacements at
O'' and H (measured at V0 = -0.5 m/s: up to 9 um while deploying, 0.91 mm in the stage-2
vibration; tests/test_launch_and_urdf.py holds that identity).  The elastic deformation is
not in the URDF: the frames are the floating frames of the beams, and the deformed shapes
(whose link end is on the sleeve) are the ``markers`` topic.

The whole umbrella (``UmbrellaRibsParams`` with ribs N > 1): the same tree for each rib k
(ribs numbered from 0, as the parameters' ``rib<k>.<name>`` overrides), its links and joints
named ``rib<k>/leaf``, ``rib<k>/link``, ``rib<k>/tip``, ``rib<k>/leaf_hinge``,
``rib<k>/link_hinge`` and ``rib<k>/leaf_tip``, with one ``sleeve`` on ``sleeve_slider``:

- ``umbrella_base``: the hub, origin on the hub axis Y at the height of the leaf hinges, +X
  toward rib 0 (the 3D model's bus frame; rib k lies at azimuth psi_k = 2 pi k / N about
  +Y, its radial axis e_r = (cos psi_k, 0, -sin psi_k), tangential e_t = e_r x e_Y).
- ``rib<k>/leaf_hinge``: revolute from ``umbrella_base`` at O_k = a e_r (a the hub radius),
  its frame turned by psi_k about +Y (rpy ``0 psi_k 0``) so that its x is e_r, its y the
  hub axis and its z, the joint's axis, e_t: the rib's plane is the joint frame's xy plane
  and the joint = alpha1 of rib k.
- ``rib<k>/link_hinge`` (about e_t, at x = l1 of rib k) = alpha2 - alpha1 of rib k;
  ``rib<k>/leaf_tip`` fixed at x = l1 + l2 of rib k (its tip mass, if any, is that link's
  inertial, at the tip offset); each rib's lengths, section and density are its own.

Loop closures of the whole umbrella: N pins, each rib's link end (x'' = l3) on the sleeve's
rim at a e_r + y_H e_Y, all left out of the tree.  No joint is a URDF ``mimic``: mimic is
linear (q = m q_master + c), and the closure is not.  For rigid ribs one coordinate, y_H
(``sleeve_slider``), determines all the others (each ``rib<k>/leaf_hinge`` and
``rib<k>/link_hinge`` through its rib's closure); with flexible ribs they are the floating
frames' own coordinates.  Either way the node publishes the position of every moving joint,
``joint_names(N)``, on joint_states, and robot_state_publisher takes them all from there
(none is computed by it).  The out-of-plane elastic displacement of O'' (the link frame's
origin is the deformed O'', off the leaf's x axis by u and w) is left out as the in-plane
one is; the ``markers`` topic draws the deformed ribs.
"""
from __future__ import annotations

import math
from xml.sax.saxutils import quoteattr

from ..core.params import UmbrellaParams
from ..core.umbrella3d.params3d import UmbrellaRibsParams

BASE, LEAF, LINK, SLEEVE, TIP = 'umbrella_base', 'leaf', 'link', 'sleeve', 'tip'
JOINTS = {'leaf_hinge': ('revolute', BASE, LEAF),
          'link_hinge': ('revolute', LEAF, LINK),
          'sleeve_slider': ('prismatic', BASE, SLEEVE),
          'leaf_tip': ('fixed', LEAF, TIP)}
#: the joints whose positions joint_states carries (leaf_tip is fixed)
MOVING_JOINTS = [n for n, (kind, _, _) in JOINTS.items() if kind != 'fixed']


def _box_link(name: str, length: float, b: float, mass: float, rgba: str) -> str:
    """Return a beam of the given length along the link's +x: visual, collision, inertia."""
    ixx = mass * 2 * b * b / 12.0
    iyy = izz = mass * (length ** 2 + b * b) / 12.0
    geometry = f'<geometry><box size="{length:.9g} {b:.9g} {b:.9g}"/></geometry>'
    origin = f'<origin xyz="{length / 2:.9g} 0 0" rpy="0 0 0"/>'
    return f"""  <link name="{name}">
    <visual>{origin}{geometry}
      <material name="{name}_colour"><color rgba="{rgba}"/></material></visual>
    <collision>{origin}{geometry}</collision>
    <inertial>{origin}<mass value="{mass:.9g}"/>
      <inertia ixx="{ixx:.9g}" ixy="0" ixz="0" iyy="{iyy:.9g}" iyz="0" izz="{izz:.9g}"/></inertial>
  </link>
"""


def _section_side(p: UmbrellaParams) -> float:
    """Return the drawn section's side b: the section height, else that of a square."""
    return p.section_height if p.section_height > 0 else math.sqrt(p.cross_section_area)


def joint_names(ribs: int = 1) -> list[str]:
    """
    Return the moving joints of the URDF for this many ribs, in joint_states' order.

    One rib: MOVING_JOINTS (leaf_hinge, link_hinge, sleeve_slider), the planar names.  N
    ribs: rib<k>/leaf_hinge and rib<k>/link_hinge for k = 0 .. N - 1, then sleeve_slider.
    """
    if ribs < 1:
        raise ValueError(f'ribs={ribs}: give at least one')
    if ribs == 1:
        return list(MOVING_JOINTS)
    return [f'rib{k}/{j}' for k in range(ribs) for j in ('leaf_hinge', 'link_hinge')] + [
        'sleeve_slider']


def urdf(params: UmbrellaParams | UmbrellaRibsParams | None = None,
         name: str = 'umbrella_sim') -> str:
    """
    Return the URDF text for these parameters (default: the thesis's data).

    The planar parameters, or the whole umbrella's with one rib: the planar URDF of rib 0's
    values (its frames from O, where the planar model has them).  N > 1 ribs: the whole
    umbrella's tree (see the module docstring).
    """
    if isinstance(params, UmbrellaRibsParams):
        params = params.validated()
        if params.ribs > 1:
            return _umbrella_urdf(params, name)
        params = params.rib(0).planar
    p = (params or UmbrellaParams()).validated()
    b = _section_side(p)
    leaf_len, link_len = p.l1 + p.l2, p.l3
    axle = p.sleeve_start_height + 0.1 * leaf_len
    top = p.l1 + p.l3                                   # y_H can never exceed l1 + l3
    m = p.mass_per_length
    parts = ['<?xml version="1.0"?>\n<!-- generated by umbrella_sim.ros.robot_description '
             'from the '
             'default parameters; do not edit (see the module for the loop closure) -->\n',
             f'<robot name={quoteattr(name)}>\n',
             f"""  <link name="{BASE}">
    <visual><origin xyz="0 {axle / 2:.9g} 0" rpy="{-math.pi / 2:.9g} 0 0"/>
      <geometry><cylinder radius="{b:.9g}" length="{axle:.9g}"/></geometry>
      <material name="axle_colour"><color rgba="0.6 0.6 0.6 1"/></material></visual>
  </link>
""",
             _box_link(LEAF, leaf_len, b, m * leaf_len, '0.9 0.6 0.1 1'),
             _box_link(LINK, link_len, b, m * link_len, '0.2 0.5 0.9 1'),
             f"""  <link name="{SLEEVE}">
    <visual><origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><box size="{3 * b:.9g} {3 * b:.9g} {3 * b:.9g}"/></geometry>
      <material name="sleeve_colour"><color rgba="0.8 0.1 0.1 1"/></material></visual>
  </link>
""",
             f"""  <!-- alpha1: leaf angle from +X (folded {p.alpha0:.6g} rad, deployed
       {p.alpha_deployed:.6g} rad) -->
  <joint name="leaf_hinge" type="revolute">
    <parent link="{BASE}"/><child link="{LEAF}"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="{math.pi / 2:.9g}" effort="0" velocity="1000"/>
  </joint>
  <!-- alpha2 - alpha1: link frame relative to the leaf frame, about O'' at x = l1 -->
  <joint name="link_hinge" type="revolute">
    <parent link="{LEAF}"/><child link="{LINK}"/>
    <origin xyz="{p.l1:.9g} 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="{-math.pi:.9g}" upper="{math.pi:.9g}" effort="0" velocity="1000"/>
  </joint>
  <!-- y_H: sleeve height on the axle; effort = F_H, acting along -Y.  Loop closure (not in
       URDF): the link's end x'' = l3 is pinned to the sleeve -->
  <joint name="sleeve_slider" type="prismatic">
    <parent link="{BASE}"/><child link="{SLEEVE}"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="{top:.9g}" effort="1e9" velocity="1000"/>
  </joint>
  <link name="{TIP}"/>
  <!-- the undeformed tip G; tip_deflection is measured from here along the leaf's axes -->
  <joint name="leaf_tip" type="fixed">
    <parent link="{LEAF}"/><child link="{TIP}"/>
    <origin xyz="{leaf_len:.9g} 0 0" rpy="0 0 0"/>
  </joint>
</robot>
"""]
    return ''.join(parts)


def _exact(*values: float) -> str:
    """Return the numbers as Python writes them back exactly (shortest round trip; no -0)."""
    return ' '.join(repr(float(v) + 0.0) for v in values)


def _joint(name: str, kind: str, parent: str, child: str, xyz, rpy=(0.0, 0.0, 0.0),
           axis: str | None = None, limit: tuple | None = None) -> str:
    """Return a joint element; limit = (lower, upper, effort); exact (round-trip) numbers."""
    text = (f'  <joint name={quoteattr(name)} type="{kind}">\n'
            f'    <parent link={quoteattr(parent)}/><child link={quoteattr(child)}/>\n'
            f'    <origin xyz="{_exact(*xyz)}" rpy="{_exact(*rpy)}"/>')
    if axis is not None:
        text += f'<axis xyz="{axis}"/>'
    if limit is not None:
        lower, upper, effort = limit
        text += (f'\n    <limit lower="{_exact(lower)}" upper="{_exact(upper)}" '
                 f'effort="{_exact(effort)}" velocity="1000"/>')
    return text + '\n  </joint>\n'


def _point_mass(mass: float, xyz=(0.0, 0.0, 0.0)) -> str:
    """Return the inertial element of a point mass at xyz ('' if the mass is 0)."""
    if mass <= 0.0:
        return ''
    return (f'    <inertial><origin xyz="{_exact(*xyz)}" rpy="0 0 0"/>'
            f'<mass value="{_exact(mass)}"/>\n'
            '      <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>\n')


def _point_mass_link(name: str, mass: float, xyz=(0.0, 0.0, 0.0)) -> str:
    """Return a link with no geometry, carrying a point mass at xyz (none if mass is 0)."""
    inertial = _point_mass(mass, xyz)
    if not inertial:
        return f'  <link name={quoteattr(name)}/>\n'
    return f'  <link name={quoteattr(name)}>\n{inertial}  </link>\n'


def _umbrella_urdf(params: UmbrellaRibsParams, name: str) -> str:
    """Return the URDF of N > 1 ribs around one sleeve (the module docstring's tree)."""
    ribs = params.ribs_list()
    a = params.hub_radius
    sides = [_section_side(r.planar) for r in ribs]
    b = max(sides)
    leaf_max = max(r.planar.l1 + r.planar.l2 for r in ribs)
    axle = params.planar.sleeve_start_height + 0.1 * leaf_max
    top = min(r.planar.l1 + r.planar.l3 for r in ribs)     # the sleeve's reach: every rib's
    rim = f'<cylinder radius="{a + 1.5 * b:.9g}" length="{3 * b:.9g}"/>'
    up = f'rpy="{-math.pi / 2:.9g} 0 0"'                   # a cylinder's axis z onto +Y
    parts = ['<?xml version="1.0"?>\n<!-- generated by umbrella_sim.ros.robot_description for '
             f'{len(ribs)} ribs; do not edit (see the module for the loop closures) -->\n',
             f'<robot name={quoteattr(name)}>\n',
             f"""  <link name="{BASE}">
    <visual><origin xyz="0 {axle / 2:.9g} 0" {up}/>
      <geometry><cylinder radius="{b:.9g}" length="{axle:.9g}"/></geometry>
      <material name="axle_colour"><color rgba="0.6 0.6 0.6 1"/></material></visual>
    <visual><origin xyz="0 0 0" {up}/><geometry>{rim}</geometry>
      <material name="hub_colour"><color rgba="0.4 0.4 0.4 1"/></material></visual>
  </link>
  <link name="{SLEEVE}">
    <visual><origin xyz="0 0 0" {up}/><geometry>{rim}</geometry>
      <material name="sleeve_colour"><color rgba="0.8 0.1 0.1 1"/></material></visual>
""" + _point_mass(params.sleeve_mass) + '  </link>\n',
             '  <!-- y_H: sleeve height on the hub axis; effort = F_H, acting along -Y.  Loop '
             "closures (not in URDF): each rib's link end x'' = l3 is pinned to the sleeve's "
             'rim at radius a -->\n',
             _joint('sleeve_slider', 'prismatic', BASE, SLEEVE, (0.0, 0.0, 0.0), axis='0 1 0',
                    limit=(0.0, top, 1e9))]
    for rib, side in zip(ribs, sides):
        p, k, psi = rib.planar, rib.index, rib.azimuth
        leaf, link, tip = f'rib{k}/{LEAF}', f'rib{k}/{LINK}', f'rib{k}/{TIP}'
        leaf_len, m = p.l1 + p.l2, p.mass_per_length
        parts += [
            f'  <!-- rib {k} at azimuth {psi:.6g} rad: alpha1 about e_t, the z of its joint '
            'frame -->\n',
            _box_link(leaf, leaf_len, side, m * leaf_len, '0.9 0.6 0.1 1'),
            _box_link(link, p.l3, side, m * p.l3, '0.2 0.5 0.9 1'),
            _point_mass_link(tip, rib.tip_mass,
                             (rib.tip_offset_x, rib.tip_offset_y, rib.tip_offset_z)),
            _joint(f'rib{k}/leaf_hinge', 'revolute', BASE, leaf,
                   (a * math.cos(psi), 0.0, -a * math.sin(psi)), (0.0, psi, 0.0), '0 0 1',
                   (0.0, math.pi / 2, 0.0)),
            _joint(f'rib{k}/link_hinge', 'revolute', leaf, link, (p.l1, 0.0, 0.0),
                   axis='0 0 1', limit=(-math.pi, math.pi, 0.0)),
            _joint(f'rib{k}/leaf_tip', 'fixed', leaf, tip, (leaf_len, 0.0, 0.0))]
    parts.append('</robot>\n')
    return ''.join(parts)


def main(argv: list[str] | None = None) -> int:
    """
    Print the URDF of the default parameters, or of name=value pairs (the node's names).

    python -m umbrella_sim.ros.robot_description [ribs=6 rib1.tip_mass=0.1 ...]: each value
    typed as a -p value is (YAML); urdf/umbrella.urdf is the output without any.  A bad pair
    or value: a message naming it on stderr, exit 2.
    """
    import sys

    from .params_file import load_yaml_as_ros
    from ..core.registry import check_known_names, REGISTRY
    from ..core.umbrella3d.params3d import names_a_rib, node_model, umbrella_parameter_names

    import yaml

    values = {}
    usage = ("give name=value pairs (ribs=6 section_height=0.012), the node's parameter "
             'names; none: the default parameters')
    for pair in sys.argv[1:] if argv is None else argv:
        if pair in ('-h', '--help'):
            print(f'python -m umbrella_sim.ros.robot_description [name=value ...]: the URDF; '
                  f'{usage}')
            return 0
        name, assign, text = pair.partition('=')
        why = (usage if not assign or not name else
               f'{name} given twice (give each once)' if name in values else None)
        if why is None:
            try:
                values[name] = load_yaml_as_ros(text)
            except (ValueError, yaml.YAMLError) as exc:
                why = f'not a value: {" ".join(str(exc).split())}'
        if why is not None:
            print(f'robot_description: {pair!r}: {why}', file=sys.stderr)
            return 2
    try:
        check_known_names([n for n in values if not names_a_rib(n)],
                          set(REGISTRY) | umbrella_parameter_names(), 'its arguments')
        text = urdf(node_model(values) if values else None)
    except ValueError as exc:
        print(f'robot_description: {exc}', file=sys.stderr)
        return 2
    print(text, end='')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
