"""``report.html`` and its panels: the page, figures, per-view rows and tables, view agreement, residuals,
passes and the WebGL viewer (``viewer.js``, package data)."""
