"""``sctd try``'s page: the HTML page and its WebSocket server (:mod:`.server`); the
page's input goes through :class:`sctd_services.input.page.PageGate`."""
