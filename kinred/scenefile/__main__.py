"""``python -m kinred.scenefile docs/scene-file.md``: rewrite the generated reference."""

import sys

from ._reference import update_page

for page in sys.argv[1:]:
    print(f"{page}: {'updated' if update_page(page) else 'up to date'}")
