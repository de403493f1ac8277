"""How rangekit runs, not what it computes: BLAS threads, freed memory, child processes, lazy
package names, numba's noalias flag, Open3D's deferred plotly viewer. Nothing here knows about scanning."""
