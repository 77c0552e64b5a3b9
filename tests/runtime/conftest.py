from .runtime_fixtures import net

__all__ = ["net"]
