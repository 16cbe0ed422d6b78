"""robocell's reconstruction core: silhouettes to a superquadric, pure functions on arrays."""
