"""``python -m daa_sil.link.dialect``: regenerate ``daa_sil.py`` from ``daa_sil.xml``."""

from . import MODULE_PATH, generate

if __name__ == "__main__":
    print(f"wrote {generate(MODULE_PATH)}")
