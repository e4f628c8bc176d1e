"""Datasets on disk: streaming netCDF4 (HDF5) writer, provenance, reading back."""
