"""§3.3: ellipse confirmation of a blob's outline and the split of a merged pair."""
