"""Processing a session into a mesh: each view decoded and cached, the views registered and fused, the
fused outputs, and many sessions on Dask."""
