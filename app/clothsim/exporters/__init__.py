"""Export the animated cloth for other tools: a USD stage or an OBJ sequence.

``api`` (:func:`clothsim.export`, the format rules), ``geometry`` (the cloth's mesh and the
colliders, format-free), ``usd`` and ``obj`` (the writers), ``commands`` (``clothsim export``).
The package is ``exporters`` so that ``clothsim.export`` can be the function. Importing it loads
nothing else: the command line registers its parser without loading the writers.
"""
