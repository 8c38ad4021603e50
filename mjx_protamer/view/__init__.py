"""Seeing the infant: offscreen rendering, body maps, videos and the live view of `protamer finetune`.

Host-side only. The learners (agents/, human/) never import this package; the commands do.
"""
