"""The bottom layer: files in and out.

``atomic``        atomic writes (temporary file + rename), output-path checks, signal clean-up
``stokes_exr``    Stokes images as OpenEXR files
``pbsdf_file``    Mitsuba ``measured_polarized`` tables (``.pbsdf``): reader, writer, coordinates
``measurements``  the Mueller-matrix measurement CSV that ``hyde-bsdf fit`` reads

May import: the standard library, NumPy, :mod:`hyde_bsdf.errors`, :mod:`hyde_bsdf.progress`
(and OpenEXR or Mitsuba lazily, inside a reader that needs them).  Every other part of the package
may import this one; it imports none of them.  The modules are imported by their own names
(``from hyde_bsdf.io.atomic import atomic_path``): importing this package loads nothing.
"""
