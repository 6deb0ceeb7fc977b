"""``python -m gcs`` = ``daa-gcs``; the way ``daa-sil run`` starts it, so it ends without the
interpreter's teardown once its command returned (:func:`daa_sil.sil.children.exit_without_teardown`),
loads the DAA kernels without numba's BLAS probe (:func:`daa_sil.daa.kernels.skip_blas_probe`), and
starts with the garbage collector relaxed (:mod:`daa_sil.runtime.process_gc`)."""

from daa_sil.runtime.process_gc import relax_for_startup

relax_for_startup()  # before the imports: they create most of the start-up's objects

from daa_sil.daa import kernels  # noqa: E402
from daa_sil.sil.children import exit_without_teardown  # noqa: E402
from gcs.cli import main  # noqa: E402

kernels.skip_blas_probe()  # nothing in this process compiles linear algebra

exit_without_teardown(main())
