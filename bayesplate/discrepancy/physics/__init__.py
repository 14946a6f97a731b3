"""The candidate physics: what the nominal model may have left out, one module each.

Every candidate implements the small interface of :class:`.base.Physics` (its parameters
with units and priors, how it changes the plate); a located one also maps and scans where
it could sit (:mod:`.location`, :mod:`.ritz_scan`) and has a reduced form
(:mod:`.reduced_model`). :mod:`.combined` makes one candidate of two.

- ``base``: the interface, the parameters, the plate's symmetries
- ``point_mass``: a glued sensor or lump (located)
- ``thickness_taper``: thicker at one end than at the other
- ``ply_misalignment``: every ply turned by the same small angle
- ``elastic_foundation``: a soft support under the whole plate
- ``local_stiffness_loss``: a rectangular region that lost stiffness (located)
- ``delamination``: a rectangular region that lost transverse shear stiffness (located)
- ``cutout``: a circular through-hole (located)
- ``cut_corner``: a corner cut off, the triangle across it
- ``point_support``: a transverse spring at a point (located)
- ``combined``: two effects at once, as one candidate
- ``reduced_model``: a modified plate solved in a small Ritz basis
- ``location``: location maps built from a candidate's effect columns
- ``ritz_scan``: where and how large a located effect could be, beyond first order

Nothing here imports :mod:`..search`: the search uses the candidates, not the other way.
"""
