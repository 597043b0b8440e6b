"""``undertow live``: sensor links, the online filter and map, the recording and the live view."""
