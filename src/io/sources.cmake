# I/O: OpenMesh-backed mesh/point readers, PCD, LAS, hierarchy files.
