"""Texture: sparkle and graininess readings of a coating."""
