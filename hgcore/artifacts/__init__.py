"""The artifact format, owned in one place: what a render writes, under which names and keys.

* ``layout``      — file names of a job's artifacts, EXR channel names (spectral bands, RGB, coherence
                    diagnostics, geometry AOVs), the band layout and the diagnostics' reference wavelength.
* ``keys``        — store keys ``jobs/<id>/…`` of every artifact, input file and chunk partial.
* ``exr``         — the one OpenEXR reader and writer (atomic writes; ``ArtifactFormatError``).
* ``pixel_sums``  — per-pixel sums of a render or chunk and the chunk partial (``.npz``) format.
* ``images``      — final images from sums: ``image.exr``, ``variance.exr``, ``preview.png``, summary.

NumPy and OpenImageIO only: the service reads artifacts with the code that writes them.
"""
