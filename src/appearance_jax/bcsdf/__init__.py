"""Fiber BCSDFs (hair, threads, barbules): functions of fiber-frame directions.

- :mod:`.fiber`: the shared fiber geometry and absorption conventions.
"""
