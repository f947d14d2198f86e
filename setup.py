"""Build step of the one compiled module, fusiond.estimator._kernels (the EKF's linear algebra and the
smoother's fold).

Everything else is in pyproject.toml. The extension is optional: without a C compiler the
install still succeeds and the estimator runs its reference backend (estimator/backend.py), which
the tests hold equal to the compiled one. -ffp-contract=off keeps a * b + c from being fused into
one rounding where the CPU has FMA (aarch64 does by default): the quaternion code then gives the
same doubles as the Python it mirrors.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "fusiond.estimator._kernels",
            ["fusiond/estimator/_kernels.c"],
            extra_compile_args=["-O2", "-ffp-contract=off"],
            optional=True,
        ),
    ]
)
