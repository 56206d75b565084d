"""Standards toolbox: ISO 6946, ISO 13786, ISO 9869-1, ISO 10456."""
