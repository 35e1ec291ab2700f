"""A user's STL on its CAD: rigid alignment, then each triangle's face and each corner's (u,v) by projection."""
