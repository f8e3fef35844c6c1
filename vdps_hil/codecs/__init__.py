"""Wire formats both ways: CAN (DBC via cantools), NMEA 0183, IMU binary."""
