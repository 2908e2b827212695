"""The prototype manipulator of 000 (Tables 1, 3, 5, 6, 7, 9), third rope completed."""
