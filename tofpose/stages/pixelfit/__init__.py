"""Pixel-level pose fit: the 6-DOF pose refined on the raw gray and distance pixels of the
matched reflectors (issue 49, item 1; ours, not the paper's).

The paper measures each reflector by one intensity-weighted centroid (Eqs. 19-20) and one
range, back-projects them (Eqs. 7-9) and fits the pose to those points (§5, Eqs. 40-52).
That throws information away: a centroid is not the projected disc centre, and one range
per blob is not the best combination of its pixels. Here the pose is fitted to the pixels
themselves, after matching (§4) has said which catalog disc each blob is:

* ``model.py``: the forward model of each disc's pixel-integrated image. The disc
  (catalog centre and diameter, on the target plane, normal the target's z axis) is
  intersected with the rays of an S x S grid of sub-cells in each pixel (the camera's
  own bearings, lens distortion included); each sub-cell's covered area is exact for a
  straight rim (the box integral of a half-plane), so the coverage is a smooth function
  of the pose. Gray: ``gain_k * coverage + background_k * (1 - coverage)``. Distance: the
  radial range to the disc plane along each sub-cell's ray, the pixel's phasors mixed by
  amplitude with the plate's (the surround) as a CW-ToF pixel mixes them.
* ``fit.py``: windows of pixels around each disc's predicted ellipse, the sensor's noise
  model (shot noise ``A + B`` for gray, ``k sqrt(A + B) / A`` for range), and a
  Levenberg-Marquardt fit over the pose (a small rotation, rad, left-multiplied, then the
  translation, mm) and the nuisance parameters (per disc a gain and a surround level, an
  optional common range offset). The surround is the plate's level where the plate fills
  a pixel and a level measured beyond it elsewhere (the plate's edge crosses the windows
  of discs near it from a few metres on). Bright spots in the surround that touch no
  disc nor its neighbours (glints) are left out. Saturated pixels are censored (a model
  at or above full scale agrees with them). The covariance is the inverse Fisher information at the
  solution, the pose block after the nuisance parameters are marginalised. It falls back
  (``PixelFitResult.ok`` False, with the reason) when the fit does not converge or a
  disc's residuals are far beyond its noise (a glint, an occluded disc), or a disc's
  core is clipped (saturated: its gain seen only on the rim's outer pixels, where the
  model's rim error makes the fit overconfident), so the caller keeps the centroid pose.

Public entry point: ``fit.fit_pose_to_pixels``.
"""
