"""Result files: HDF5 written step by step on rank 0, with an XDMF file beside it."""
