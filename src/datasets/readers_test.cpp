#include <gtest/gtest.h>
TEST(Readers, Placeholder) {}
