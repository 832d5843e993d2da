"""The suite's numerics are pinned before numpy loads (tests/__init__.py), on every x86 CPU
with AVX2 and FMA: OpenBLAS's Haswell kernels, numpy's AVX2 loops."""

import os

import pytest
from threadpoolctl import threadpool_info

from tests import cpu_flags as _flags  # the package pinned the numerics on import


@pytest.mark.skipif(not {"avx2", "fma"} <= _flags(), reason="no AVX2+FMA x86 CPU")
def test_blas_and_numpy_run_the_pinned_kernels():
    from numpy._core._multiarray_umath import __cpu_features__

    arch = [i.get("architecture") for i in threadpool_info() if i["internal_api"] == "openblas"]
    assert arch and set(arch) == {os.environ.get("OPENBLAS_CORETYPE", "Haswell")}
    if "NPY_DISABLE_CPU_FEATURES" in os.environ and "avx512f" in _flags():
        assert not __cpu_features__.get("X86_V4")
