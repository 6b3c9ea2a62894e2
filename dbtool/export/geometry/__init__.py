"""The export's geometry: the design's fields, their meshes (marching tetrahedra), voxels of a
solid and the Voronoi lattice infill, all in millimetres."""
