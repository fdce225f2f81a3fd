"""Scenes: the shipped scenes found by name, and scene texts varied by a patch (budget, report)."""
