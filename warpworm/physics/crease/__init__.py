"""Crease patterns: the worm's triangular-prism bellows and any other triangulated origami, as NumPy data.

A :class:`CreasePattern` is the bar-and-hinge description of an origami sheet (Liu & Paulino's MERLIN model, the
paper's Kangaroo model): every mesh edge is a bar, every interior edge is a hinge with a label (mountain / valley /
flat) and a rest fold angle. Everything is float64, SI (m, rad), host-side; the solver uploads it.

Geometry of the worm (paper §III, Fig. 3; the triangulation is ours)
-----------------------------------------------------------------------------------------
A tube with an equilateral triangular cross-section of side ``a`` runs along +x, tail at x = 0, one face on the floor
z = 0. There are ``2 n + 1`` cross-sections, one every half unit (``s = 0 .. 2n``): even ``s`` are the unit
boundaries (full triangles of side ``a``), odd ``s`` are the unit middles (inset triangles: every face moved inward
by ``b sin(α/2)``, shrunk about the same axis). Between two sections each of the three faces is a planar trapezoid
of slant width ``b``, tilted by ±α/2 from the axis, so a unit (two panels of width ``b`` meeting at interior angle
π − α) is ``u = 2 b cos(α/2)`` long: eq. (7). Each trapezoid is split into two triangles by a diagonal (a flat
crease); the diagonal alternates between half units so every unit is mirror-symmetric about its middle.

Creases and labels:
- transverse creases at the unit middles: VALLEY, rest +α (the tube is pinched in there);
- transverse creases at interior unit boundaries: MOUNTAIN, rest −α (ridges);
- the prism's corner creases (section s vertex k to section s + 1 vertex k): MOUNTAIN, rest angle = their built
  dihedral (about −2π/3 − a little; exactly −(π − the corner's dihedral), see :func:`dihedral_angles`), since a
  prism corner is a ridge seen from outside and its angle is set by the prism, not by α;
- trapezoid diagonals: FLAT, rest 0; the open ends' edges: BOUNDARY (no hinge).

Signed fold angle (the convention of ``hinge_rest_angle`` and of the dynamics)
-----------------------------------------------------------------------------
Hinge stencil ``(i, j, k, l)``: shared edge j–k; wing ``i`` belongs to the triangle oriented (i, j, k) and wing
``l`` to the triangle oriented (l, k, j) (both in the mesh's consistent, outward orientation). With
``n1 = (x_j − x_i) × (x_k − x_i)``, ``n2 = (x_k − x_l) × (x_j − x_l)`` (outward normals of the two wings) and
``e = (x_j − x_k) / |x_j − x_k|``::

    ψ = atan2((n1 × n2) · e, n1 · n2)      ∈ (−π, π],   0 = flat

ψ > 0 (valley) when the wings fold toward the side their outward normals point to, i.e. ``n1 · (x_l − x_j) > 0``;
ψ < 0 is a mountain. In MERLIN's notation (r_ij = x_i − x_j, r_kj = x_k − x_j, r_kl = x_k − x_l, same node order)
ψ = π − θ_MERLIN, so ∂ψ/∂x_i = |e| n1 / |n1|², ∂ψ/∂x_l = |e| n2 / |n2|² (see :func:`dihedral_gradients`).

Foldability (what the dynamics must know)
-----------------------------------------
Any triangulated tube whose open ends are triangles has E = 3V − 6 bars: generically isostatic, and this one is
(rank of the rigidity matrix = 3V − 6). With every bar stiff, squashing the worm strains bars: at EA = 1e4 N its
axial stiffness is ≈ 4.3e4 N/m (:func:`compression_mode`), far beyond what the IPMs can push. The VALLEY bars (the
rings at the unit middles, 3 per unit) are the minimal set that must give: without them the tube has 3 n internal
mechanisms, axial shortening among them, with every other bar at zero strain to first order (finite check: 20 %
shortening with the other bars under 4e-6 strain, the valley rings at −10 … +6 %). Physically that is the paper's
faces bending near the mid creases. So the solver should give the VALLEY-labelled bars a much lower axial stiffness.

Modules: ``pattern`` (CreasePattern, mount_poses, compression_mode), ``worm`` (build_worm, rest_alpha, ...),
``geometry`` (dihedral angles and gradients, lengths, rigidity, mount frames), ``topology`` (edges, hinges,
segments, keypoints), ``files`` (load_pattern, export_mesh). Every public name is importable from here.
"""

from __future__ import annotations

from warpworm.ids import BOUNDARY, FLAT, MOUNTAIN, VALLEY
from warpworm.physics.crease.files import export_mesh, load_pattern
from warpworm.physics.crease.geometry import (dihedral_angles, dihedral_gradients, edge_lengths, frame_from_vertices,
                                              rigidity_matrix)
from warpworm.physics.crease.pattern import LABEL_NAMES, MOUNT_NAMES, CreasePattern, compression_mode, mount_poses
from warpworm.physics.crease.topology import NUM_SEGMENTS
from warpworm.physics.crease.worm import (build_worm, rest_alpha, unit_length, worm_rest_state, worm_triangles,
                                          worm_vertices)
