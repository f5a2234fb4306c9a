import pytest

from services.semantic_fusion import DISTRIBUTION_CLASSES, SemanticFusionError, class_columns
from shared.vocabulary import SemanticClass


def test_class_columns_maps_names_aliases_and_strangers() -> None:
    columns = class_columns(["Wall", "person", "upright", "crate"])
    assert [DISTRIBUTION_CLASSES[c] for c in columns] == [
        SemanticClass.WALL, SemanticClass.HUMAN, SemanticClass.RACK, SemanticClass.UNKNOWN]


def test_class_columns_rejects_none_as_an_observation() -> None:
    with pytest.raises(SemanticFusionError, match="cannot label"):
        class_columns(["none"])
