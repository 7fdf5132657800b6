"""Inverse rendering: BSDF parameters -- one global value or per-texel maps -- from Stokes images.

It uses the renderer and produces parameter maps, so it sits right of ``render`` (may import
``hyde_bsdf.io``, ``model``, ``mitsuba``, ``fit``, ``render``; only ``hyde_bsdf.app`` imports it).  Modules:

``loss``          the Stokes-image loss (:class:`StokesLoss`), its mask, the map regulariser
``scalar``        one global rms_slope, eta, k from one image (:func:`invert`; spectral polarized)
``observations``  :class:`Observation`, texture keys, Stokes renders, the UV-coverage pass, the plane scene
``acquisition``   the designed observation set: views, lights, polarizer states (:func:`design_acquisition`)
``maps``          per-texel maps (:func:`invert_maps`): set-up, loss, step, update, uncertainty
``adam``          the one optimiser of both: Adam on log(value), its schedule and average
``uncertainty``   per-texel standard errors (Gauss-Newton information, forward-mode AD), warnings
``analyzer``      raw analyzer frames / DoFP mosaics -> Stokes images with propagated sigma, the camera noise
``camera_data``   Stokes inputs as cameras give them (measured components, sigma, masks), calibrated rigs
``tiles``         per-texel maps in tiles of texels, each an independent task on an executor (:func:`invert_maps_tiled`)

``hyde_bsdf.inverse`` itself exports what a user calls (:data:`__all__`): the two inversions and
their options and results, the tiled one, the observations and the loss, the designed and the
calibrated acquisitions, the parameter tables and the warnings; every other name is in its module.

Texture-valued parameters (SVBRDF, :func:`invert_maps`): a scene whose BSDF takes
``<texture name="alpha" type="bitmap">`` (Beckmann alpha; hyde and roughconductor alike,
key ``...bsdf.alpha.data``), ``rms_slope`` (``rms_slope.data``) or index textures
(``eta.data``, ``k.data``; constants ``eta.value``/``k.value`` are fitted as one number) is
matched to one or more reference Stokes images (:class:`Observation`: scene, sensor, reference,
mask, weight; several views and lights), per texel, with Adam on log(value), the same Stokes loss
per image and an optional smoothness regulariser (:func:`smoothness`, weight lambda documented
there).  :func:`texel_coverage` finds the texels the images see (a UV-coverage pass), over which
errors are reported.  The validation (hyde_bsdf/validation/svbrdf_inverse.py) and the benchmark
(benchmarks/bench_inverse.py) use :data:`MAP_VARIANT` = ``llvm_ad_mono_polarized`` and
:func:`plane_scene_dict` (a textured plane, 3 views in one ``batch`` sensor, one point light per
scene).  Per-texel gradients: the rendering depends on exactly the texels the coverage pass finds
(tests/test_inverse_maps.py: dL/dalpha != 0 there and only there).

Command line: :mod:`hyde_bsdf.app.invert` (``hyde-bsdf invert``; docs/cli.md).
"""

from hyde_bsdf.inverse._common import NotConvergedWarning
from hyde_bsdf.inverse.acquisition import design_acquisition, synthetic_observations
from hyde_bsdf.inverse.camera_data import observations_from_files
from hyde_bsdf.inverse.loss import StokesLoss
from hyde_bsdf.inverse.maps import MapInversionResult, MapOptions, invert_maps
from hyde_bsdf.inverse.observations import MAP_PARAMETERS, Observation
from hyde_bsdf.inverse.scalar import PARAMETERS, InversionOptions, InversionResult, invert, prepare
from hyde_bsdf.inverse.tiles import Capture, invert_maps_tiled
from hyde_bsdf.inverse.uncertainty import BilinearFilterWarning, UnidentifiedParameterWarning

__all__ = ["invert", "InversionOptions", "InversionResult", "invert_maps", "MapOptions", "MapInversionResult",
           "invert_maps_tiled", "Capture", "Observation", "StokesLoss", "design_acquisition", "synthetic_observations",
           "observations_from_files", "prepare", "PARAMETERS", "MAP_PARAMETERS", "UnidentifiedParameterWarning",
           "NotConvergedWarning", "BilinearFilterWarning"]
