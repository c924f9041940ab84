"""The plumbing every stage shares: the error type and one-line CLI errors
(:mod:`~quadsim.core.errors`), atomic files (:mod:`~quadsim.core.files`), argument checks
(:mod:`~quadsim.core.args`), the task executor for processes and Ray
(:mod:`~quadsim.core.executor`), and the frame conventions with their quaternion math
(:mod:`~quadsim.core.frames`: world z up, body x forward / y left / z up, quaternions
scalar-first, body to world).

Imports nothing else from quadsim: every other stage may import it.
"""
