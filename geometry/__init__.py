"""gmsh builders of tagged meshes for the scenes and validation specimens, and .msh import."""
