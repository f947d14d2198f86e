"""Build step of the compiled modules: fusiond.estimator._kernels (the EKF's linear algebra) and _rts
(the smoother's fold).

<<<<<<< HEAD
Everything else is in pyproject.toml. The extensions are optional: without a C compiler the
install still succeeds and the estimator runs its numpy reference paths (ekf.py, smoother.py), which the
tests hold equal to the compiled one. -ffp-contract=off keeps a * b + c from being fused into
=======
Everything else is in pyproject.toml. The extension is optional: without a C compiler the
install still succeeds and the estimator runs its reference backend (estimator/backend.py), which
the tests hold equal to the compiled one. -ffp-contract=off keeps a * b + c from being fused into
>>>>>>> backend
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
        # the smoother's fold (smoother.py): only a replay with --smooth or a fixed-lag output loads it
        Extension(
            "fusiond.estimator._rts",
            ["fusiond/estimator/_rts.c"],
            extra_compile_args=["-O2", "-ffp-contract=off"],
            optional=True,
        ),
    ]
)
