"""Inverse rendering: BSDF parameters -- one global value or per-texel maps -- from Stokes images.

It uses the renderer and produces parameter maps, so it sits right of ``render`` (may import
``hyde_bsdf.io``, ``model``, ``mitsuba``, ``fit``, ``render``; only ``hyde_bsdf.app`` imports it).  Modules:

``loss``          the Stokes-image loss (:class:`StokesLoss`), its mask, the map regulariser
``scalar``        one global rms_slope, eta, k from one image (:func:`invert`; spectral polarized)
``observations``  :class:`Observation`, texture keys, Stokes renders, the UV-coverage pass, the plane scene
``acquisition``   the designed observation set: views, lights, polarizer states (:func:`design_acquisition`)
``maps``          per-texel maps (:func:`invert_maps`): set-up, loss, step, update, uncertainty
``uncertainty``   per-texel standard errors (Gauss-Newton information, forward-mode AD), warnings
``memory``        the memory estimate of a differentiable render, checked before an inversion
``analyzer``      raw analyzer frames / DoFP mosaics -> Stokes images with propagated sigma, the camera noise
``camera_data``   Stokes inputs as cameras give them (measured components, sigma, masks), calibrated rigs
``tiles``         per-texel maps in tiles of texels, each an independent task on an executor (:func:`invert_maps_tiled`)

Every public name of these modules is importable from ``hyde_bsdf.inverse`` itself.

Texture-valued parameters (SVBRDF, :func:`invert_maps`): a scene whose BSDF takes
``<texture name="alpha" type="bitmap">`` (Beckmann alpha; hyde and roughconductor alike,
key ``...bsdf.alpha.data``), ``rms_slope`` (``rms_slope.data``) or index textures
(``eta.data``, ``k.data``; constants ``eta.value``/``k.value`` are fitted as one number) is
matched to one or more reference Stokes images (:class:`Observation`: scene, sensor, reference,
mask, weight; several views and lights), per texel, with Adam on log(value), the same Stokes loss
per image and an optional smoothness regulariser (:func:`smoothness`, weight lambda documented
there).  :func:`texel_coverage` finds the texels the images see (a UV-coverage pass), over which
errors are reported.  The validation (validation/svbrdf_inverse.py) and the benchmark
(benchmarks/bench_inverse.py) use :data:`MAP_VARIANT` = ``llvm_ad_mono_polarized`` and
:func:`plane_scene_dict` (a textured plane, 3 views in one ``batch`` sensor, one point light per
scene).  Per-texel gradients: the rendering depends on exactly the texels the coverage pass finds
(tests/test_inverse_maps.py: dL/dalpha != 0 there and only there).

Command line (:mod:`hyde_bsdf.app.invert`; errors: one line on stderr, exit 2; Ctrl-C: exit 130; progress per iteration on
stderr; output paths and memory checked before any rendering; outputs written atomically)::

    hyde-bsdf invert [--scene SCENE.xml [--target PREFIX] | (built-in sphere)] [--truth rms_slope=0.3,eta=1.5,k=3]
                     [--reference REF.exr] [--start rms_slope=0.6,eta=3,k=6]
                     [--fit rms_slope,eta,k] [--loss stokes|s0] [--iterations 200]
                     [--spp 16] [--spp-ref 512] [--res 64] [--lr 0.05] [--seed 0] [-o OUTDIR]

writes OUTDIR/invert_history.csv and OUTDIR/invert.png (loss and parameter trajectories).
Texture mode::

    hyde-bsdf invert --maps [--scene S1.xml --reference R1.exr [--mask M1.png] ...
                     | --preset dielectric|metal [--noise 0.01]
                     | (built-in plane, 3 views x 2 lights, truth map of --map-size 32)]
                     [--fit alpha[,eta,k][,specular_reflectance]] [--start alpha=0.3,eta=1.6]
                     [--regularizer tv|l2 --weight 0.1] [--no-uncertainty]
                     [--iterations 100] [--spp 4] [--spp-ref 64] [--res 80] [--sensor 0] [-o OUTDIR]
    hyde-bsdf invert --maps --scene SAMPLE.xml --camera CAMERA.json --light LIGHT.json --reference R.exr ...
                     [--tiles N|RxC [--workers K | --scheduler tcp://HOST:8786]]

writes OUTDIR/invert_maps_history.csv, OUTDIR/NAME.npy and NAME.exr per fitted map (rows along
v; load the EXR as a ``bitmap`` texture with ``raw`` true and ``filter_type`` nearest; NaN where no
picture sees the texel), NAME_stderr.npy/.exr (per-texel standard errors; NaN where not valid),
NAME_seen.npy/.exr (1 where a picture sees the texel) and OUTDIR/invert_maps.png.  ``--preset`` captures the built-in synthetic sample
(:func:`example_material`) in the designed acquisition (:func:`design_acquisition`; --res default
4 x --map-size, so that texels span pure pixels) and reports the errors against its truth.
"""

from hyde_bsdf.inverse._common import Y_WEIGHTS, NotConvergedWarning
from hyde_bsdf.inverse.loss import (REFERENCE_RANGE, StokesLoss, channel_names, check_reference_scale,
                                    interior_mask, smoothness, stokes_images)
from hyde_bsdf.inverse.acquisition import (Acquisition, Configuration, acquisition_scene_dict,
                                           design_acquisition, example_material, fixed_rig_acquisition,
                                           predicted_stderr, synthetic_observations)
from hyde_bsdf.inverse.maps import (LogAdam, MapInversionResult, MapProblem, filters_bilinearly, invert_maps, map_loss,
                                    map_step, map_uncertainty)
from hyde_bsdf.inverse.uncertainty import (CONVERGENCE_THRESHOLD, MISFIT_P, STDERR_THRESHOLD, BilinearFilterWarning, Uncertainty,
                                           UnidentifiedParameterWarning)
from hyde_bsdf.inverse.observations import (LIGHTS, MAP_PARAMETERS, MAP_VARIANT, VIEW_AZIMUTHS, Observation,
                                            example_maps, film_channels, map_keys, plane_scene_dict,
                                            pixel_texels, render_stokes, render_stokes_np,
                                            texel_coverage)
from hyde_bsdf.inverse.analyzer import (CameraNoise, StokesEstimate, analysis_matrix, retarder_mueller,
                                        simulate_capture, simulate_frames, simulate_mosaic, stokes_from_frames,
                                        stokes_from_mosaic, stokes_sigma, write_stokes_estimate)
from hyde_bsdf.inverse.camera_data import (calibrated_observations, camera_files, camera_observation,
                                           camera_reference, observations_from_files)
from hyde_bsdf.inverse.tiles import (Capture, Tile, invert_maps_tiled, pixel_tiles, plan_tiles, run_tile, stitch_tiles,
                                     tile_bounds)
from hyde_bsdf.inverse.scalar import (PARAMETERS, RANGES, START, TRUTH, VARIANT, InversionResult,
                                      check_gradients, finite_difference_gradient, invert, trajectory_converged, load_scene, loss_and_gradient,
                                      parameter_keys, prepare, render_reference, scene_dict,
                                      write_history)

__all__ = ["CameraNoise", "StokesEstimate", "analysis_matrix", "retarder_mueller", "simulate_capture",
           "simulate_frames", "simulate_mosaic", "stokes_from_frames", "stokes_from_mosaic", "stokes_sigma",
           "write_stokes_estimate", "calibrated_observations", "camera_observation", "camera_reference",
           "observations_from_files", "camera_files", "Capture", "Tile", "invert_maps_tiled", "pixel_tiles", "plan_tiles",
           "run_tile", "stitch_tiles", "tile_bounds", "VARIANT", "PARAMETERS", "TRUTH", "START", "RANGES", "prepare", "scene_dict", "load_scene",
           "parameter_keys", "stokes_images", "channel_names", "interior_mask", "StokesLoss", "REFERENCE_RANGE",
           "check_reference_scale", "render_reference",
           "InversionResult", "invert", "check_gradients", "loss_and_gradient", "finite_difference_gradient",
           "write_history", "MAP_PARAMETERS", "MAP_VARIANT", "map_keys", "film_channels",
           "render_stokes", "render_stokes_np", "Observation", "texel_coverage", "smoothness",
           "MapInversionResult", "invert_maps", "MapProblem", "map_loss", "map_step", "LogAdam", "map_uncertainty",
           "Uncertainty", "UnidentifiedParameterWarning", "STDERR_THRESHOLD", "NotConvergedWarning",
           "BilinearFilterWarning", "CONVERGENCE_THRESHOLD", "MISFIT_P", "trajectory_converged", "filters_bilinearly", "pixel_texels", "Configuration",
           "Acquisition", "design_acquisition", "acquisition_scene_dict", "synthetic_observations", "example_material", "fixed_rig_acquisition", "predicted_stderr", "example_maps", "plane_scene_dict", "VIEW_AZIMUTHS", "LIGHTS", "Y_WEIGHTS"]
