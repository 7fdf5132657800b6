"""The Mitsuba 3 plugin ``hyde``: a Dr.Jit-traced ``mi.BSDF`` and what it needs.

``plugin`` (the BSDF class and :func:`register`), ``optics`` (its vector-form facet optics:
Fresnel Mueller matrix, V-groove, DHR lookup), ``frames`` (Mitsuba's Stokes bases against the
paper's, for comparisons), ``chi2`` (a polarization-aware adapter for Mitsuba's chi^2 test),
``variants`` (choosing a usable variant: the LLVM version guard, the CUDA guard), ``log`` (Mitsuba log
messages repeated per scene, once per run).

The plugin is an independent derivation of the evaluator: it reads the model's data (the DHR
table, the parameter ranges), never its formula code, and the two are tested against each other.
"""
