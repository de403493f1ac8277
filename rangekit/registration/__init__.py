"""Registration of range scans: ICP, GPA, synchronisation, coarse alignment, multi-view (Fusiello ch. 14-15)."""
