"""Cython extensions of core_cy; everything else is declared in pyproject.toml."""
import numpy as np
from Cython.Build import cythonize
from setuptools import Extension, setup

KERNELS = ["_auto_segment_cy", "_carve_cy", "_edges_cy", "_grasp_cy", "_least_squares_cy", "_silhouette_fit_cy",
           "_superquadric_cy"]

extensions = [
    Extension(
        f"robocell.core_cy.{name}",
        [f"robocell/core_cy/{name}.pyx"],
        include_dirs=[np.get_include()],
        define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
        extra_compile_args=["-O3"],
    )
    for name in KERNELS
]

setup(ext_modules=cythonize(extensions, compiler_directives={"language_level": "3"}))
