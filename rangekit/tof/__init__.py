"""Time of flight: range from pulsed round-trip times and from continuous-wave correlation samples.

Fusiello ch. 13.3. Units: metres, seconds, hertz, radians; images (H, W) in camera pixels.

Pulsed: light returns after ``dt``, so the radial distance is ``r = c dt / 2`` (1 mm is 6.7 ps of
round trip).

Continuous wave (CW): the emitter is modulated at ``f`` (wavelength ``lambda = c / f``); the light
returning from range ``r`` is delayed in phase by ``phi = 2 pi f 2 r / c`` (eq. 13.8). The pixel
correlates it with the reference shifted by ``theta_k`` and integrates, giving sample ``k``::

    S_k = B + A cos(phi - theta_k)          (offset B, amplitude A, any >= 3 distinct steps theta_k)

Writing ``S_k = B + a cos(theta_k) + b sin(theta_k)`` with ``a = A cos(phi)``, ``b = A sin(phi)`` makes
the N-bucket estimate a linear least-squares fit (:func:`phase_amplitude_offset`). One frequency gives
``r = n lambda/2 + phi lambda / (4 pi)`` (eq. 13.9): known modulo ``lambda / 2`` (the *unambiguous
range*, 1.875 m at 80 MHz). Several frequencies fix the wrap counts ``n_j``: the combined unambiguous
range is ``c / (2 gcd(f_j))`` (16/80/120 MHz: 18.75 m; 80/100 MHz: 7.5 m). :func:`unwrap_ranges`
searches every admissible wrap count of the finest frequency, rounds the others to it and keeps the
candidate whose per-frequency ranges agree best, weighted by their inverse variances.

Noise: with per-sample noise ``sigma_s`` (shot noise of the offset plus read noise, in the samples'
units) the phase noise is ``sigma_phi = sqrt(2 / N) sigma_s / A`` and the range noise
``sigma_r = c sigma_phi / (4 pi f)``; unwrapped ranges of several frequencies are averaged with weights
``1 / sigma_r^2``, so ``sigma_r`` of the combination is ``(sum 1 / sigma_r,j^2)^(-1/2)``.

A ToF camera measures radial distance along the pixel's ray, not ``z``: :func:`range_to_depth` and
:func:`range_to_points` convert with the camera model (lens distortion included).
"""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
