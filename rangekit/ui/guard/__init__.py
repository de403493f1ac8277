"""What keeps ``rangekit ui`` safe from the machine it runs on, apart from the token gate
(:mod:`rangekit.ui.access`): the response headers, the request body's size and shape, the JSON fields' types, the
names a page may give a folder, the connections uvicorn holds. ``__init__`` re-exports nothing."""
