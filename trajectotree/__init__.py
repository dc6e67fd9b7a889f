"""TrajectoTree: contact-sequence tree search meets contact-implicit trajectory optimization."""

__version__ = "0.1.0"
