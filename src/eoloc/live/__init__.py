"""eoloc live: KLV streams as they arrive (:mod:`.session`, :mod:`.sources`)."""
