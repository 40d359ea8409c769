"""Numerical rules shared by every render backend (those of the reference 3DGS / gsplat rasterizers).

- Pixel (px, py) has its centre at (px + 0.5, py + 0.5) in the coordinates of
  u = fx * x / z + cx, v = fy * y / z + cy.
- Gaussians with camera-space z < NEAR_PLANE or z > FAR_PLANE are culled (behind-camera included).
- The EWA Jacobian uses x/z, y/z clamped to the image extent plus 0.3 tan(fov/2) on each side
  (gsplat's form of 3DGS's 1.3 * tan(fov/2) clamp); the projected centre itself is not clamped.
- A 2D low-pass EPS2D * I is added to every projected covariance; a Gaussian whose 2D covariance
  determinant is not finite and > 0 is culled (determinant guard).
- alpha = min(ALPHA_MAX, opacity * exp(power)) with no gradient when clamped; Gaussians whose
  alpha < ALPHA_MIN at a pixel are skipped there; a Gaussian with power > 0 (numerically invalid)
  is skipped.
- Front to back in order of camera-space z (stable by index for ties); a pixel stops before the
  Gaussian that would bring its transmittance to T_MIN or below (that Gaussian is excluded).
- Screen extent (for tiles): extend = min(EXTEND_MAX, sqrt(2 log(opacity / ALPHA_MIN))) sigmas per
  axis, radius_x = ceil(extend * sqrt(cov_xx)), likewise y; Gaussians with opacity < ALPHA_MIN, or
  whose box misses the image, are culled. Beyond that box alpha < ALPHA_MIN, so tiling changes nothing.
- Quaternions are normalised (zero -> identity), log-scales are clamped before exp.
"""
NEAR_PLANE = 0.01
FAR_PLANE = 1e10
EPS2D = 0.3
ALPHA_MAX = 0.999
ALPHA_MIN = 1.0 / 255.0
T_MIN = 1e-4
TILE_SIZE = 16
EXTEND_MAX = 3.33
FOV_CLAMP_MARGIN = 0.3
