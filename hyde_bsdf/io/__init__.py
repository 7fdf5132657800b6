"""The bottom layer: files in and out.

``trust``         caches the package reads back: ownership, permissions and file type checked as
                  ssh does; the per-user secret that seals them

May import: the standard library, NumPy and :mod:`hyde_bsdf.errors`.  Every other part of the
package may import this one; it imports none of them.  The modules are imported by their own
names (``from hyde_bsdf.io.trust import open_trusted``): importing this package loads nothing.
"""
