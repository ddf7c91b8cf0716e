"""Helpers that know nothing of geolocation: names imported on first use (:mod:`.lazy`) and a
sorted search for many queries (:mod:`.search`)."""
