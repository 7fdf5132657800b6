"""The bottom layer: files in and out.

``input_gate``    every input: regular files or ``-`` (stdin read once), size and field limits,
                  table dimensions checked before allocation
``output_gate``   every output: no special files, no input overwritten, locks, folder checks
``memory``        the one memory check (the only reader of the kernel's memory figures)
``ior``           Mitsuba's ``data/ior`` material names and files
``atomic``        atomic writes (temporary file + rename), output-path checks, signal clean-up
``stokes_exr``    Stokes images as OpenEXR files
``pbsdf_file``    Mitsuba ``measured_polarized`` tables (``.pbsdf``): reader, writer, coordinates
``measurements``  the Mueller-matrix measurement CSV that ``hyde-bsdf fit`` reads
"""
