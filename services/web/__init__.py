"""The operator's live web page (stb web)."""
