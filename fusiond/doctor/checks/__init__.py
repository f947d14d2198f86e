"""The doctor's checks, one module each: the check, the analysis only it uses, and the thresholds it decides by.

Each module holds one check class (``check.BaseCheck``); ``registry`` finds them here and derives the
order they run in from what each declares. Analysis that several checks share stays in the doctor's own
modules (``heading``, ``gyro``, ``mounting``, ...), with the thresholds it decides by.
"""

__all__: list[str] = []
