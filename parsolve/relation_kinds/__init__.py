"""The relation kinds a scene's ``[[relations]]`` entries name (``type``): each a module with
its own keys and rows, and one entry in ``registry``."""
