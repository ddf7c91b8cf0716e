"""eoloc as a service: the HTTP JSON API (:mod:`.api`)."""
