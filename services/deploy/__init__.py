"""The lab's deployment files, rendered from its lab file: ``stb deploy render``."""
