"""Ground products of whole frames: the frame geometry of a MISB ST 0601 packet (:mod:`.frame`),
frame footprints (:mod:`.footprint`), orthorectified frames (:mod:`.rectify`) and mosaics of a pass
(:mod:`.mosaic`)."""
