// SPDX-License-Identifier: MIT
#include "render/diffusion.h"

#include <gtest/gtest.h>

#include <cmath>

#include "solver/material.h"

namespace translume {
namespace {

}  // namespace
}  // namespace translume
