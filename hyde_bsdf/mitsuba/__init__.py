"""The Mitsuba 3 plugin ``hyde``: a Dr.Jit-traced ``mi.BSDF`` and what it needs.

``plugin`` (the BSDF class and :func:`register`), ``optics`` (its vector-form facet optics:
Fresnel Mueller matrix, V-groove, DHR lookup), ``frames`` (Mitsuba's Stokes bases against the
paper's, for comparisons), ``chi2`` (a polarization-aware adapter for Mitsuba's chi^2 test),
``variants`` (choosing a usable variant: the LLVM version guard, the CUDA guard), ``log`` (Mitsuba log
messages repeated per scene, once per run).

May import: ``hyde_bsdf.model`` for *data* only (the DHR table and parameter ranges), never its
formula code: the plugin is an independent derivation of the evaluator, and the two are tested
against each other.  Importing this subpackage does not import Mitsuba; using it does.
"""
