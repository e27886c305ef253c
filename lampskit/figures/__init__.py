"""The paper's figures (matplotlib, headless): :mod:`.demo` (Figs. 4-5, the skill), :mod:`.primitives` (Figs. 6-7),
both drawn on :mod:`.canvas` (the Agg backend and the PNG writer)."""

__all__ = ["canvas", "demo", "primitives"]
