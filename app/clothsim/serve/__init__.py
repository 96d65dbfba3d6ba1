"""``clothsim serve``: the course's interactive GUI in a browser, drawn by the headless renderer.

``engine`` owns the simulation and the renderer in one worker thread (GL contexts are bound to a
thread), ``protocol`` checks the page's messages, ``orbit`` is the dragged camera, ``recorder``
writes clips through the CLI's writers, ``hub`` sends frames and messages to the pages, ``app`` is
the aiohttp server and ``command`` the CLI.
Importing this package imports neither aiohttp nor the renderer.
"""
