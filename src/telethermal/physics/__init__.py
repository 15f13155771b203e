"""Contact physics: materials, closed forms, layered conduction, sensors, scenes."""
