"""Optional 3D solid crossing rail (DESIGN.md §3): gmsh mesh, scikit-fem assembly,
distributing coupling to beam nodes, sparse Craig–Bampton.

Pipeline, one module per step: :mod:`.section` (polygon, section properties)
-> :mod:`.mesh` (10-node tetrahedra by gmsh) -> :mod:`.fem`
(K, M with scikit-fem; node and face sets; the section's shear coefficient) -> :mod:`.coupling` (distributing
coupling, tie to beam nodes) -> :mod:`.reduction` (sparse Craig–Bampton) ->
:mod:`.body` (the reduced solid rail with its retained coordinates).

gmsh and scikit-fem are imported only inside the functions that need them.
"""
from .body import SolidRail, SolidRailParams, solid_rail
from .coupling import DistributingCoupling, TiedBody, distributing_coupling, rigid_motion, surface_coupling, tie
from .fem import SurfaceMoments, assemble, faces_on_plane, nodes_on_line, seat_nodes, shear_coefficient, surface_moments
from .mesh import CrossingGeometry, rail_solid_mesh, refine
from .reduction import SparseReducedBody, craig_bampton_sparse, static_correction_sparse
from .section import RailSection, polygon_properties, rail_60e1_like

__all__ = ["SolidRail", "SolidRailParams", "solid_rail", "DistributingCoupling", "TiedBody",
           "distributing_coupling", "rigid_motion", "surface_coupling", "tie", "assemble",
           "SurfaceMoments", "surface_moments", "faces_on_plane", "nodes_on_line", "seat_nodes", "CrossingGeometry",
           "rail_solid_mesh", "refine", "SparseReducedBody", "craig_bampton_sparse",
           "static_correction_sparse", "RailSection", "polygon_properties", "rail_60e1_like",
           "shear_coefficient"]
