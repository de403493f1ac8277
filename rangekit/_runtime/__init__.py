"""How rangekit runs, not what it computes: BLAS threads, freed memory, child processes, lazy
package names, numba's noalias flag, Open3D's deferred plotly viewer, the front door's argument checks. Nothing here knows about scanning."""
