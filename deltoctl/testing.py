"""The pytest plugin deltoctl registers, for users' own bring-up test suites.

Kept import-light: pytest loads it in every run.
"""

from __future__ import annotations
