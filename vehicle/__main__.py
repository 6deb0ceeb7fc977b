"""``python -m vehicle`` = ``daa-vehicle``; the way ``daa-sil run`` starts it, so it ends without the
interpreter's teardown once its command returned (:func:`daa_sil.sil.children.exit_without_teardown`),
and loads the DAA kernels without numba's BLAS probe (:func:`daa_sil.daa.kernels.skip_blas_probe`)."""

from daa_sil.daa import kernels
from daa_sil.sil.children import exit_without_teardown
from vehicle.cli import main

kernels.skip_blas_probe()  # nothing in this process compiles linear algebra

exit_without_teardown(main())
