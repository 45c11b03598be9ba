/* The layout of the plant instance as this build compiled it (plant_layout.h). */
#include "plant_layout.h"

#include "plant.h"

#define PLANT_LAYOUT_SIZE(t) sizeof(t),
#define PLANT_LAYOUT_OFFSET(f) offsetof(plant, f),
#define PLANT_LAYOUT_SIZE_NAME(t) ";sizeof(" #t ")"
#define PLANT_LAYOUT_OFFSET_NAME(f) ";offsetof(plant, " #f ")"

static const size_t layout[] = {sizeof(plant), PLANT_LAYOUT_BLOCKS(PLANT_LAYOUT_SIZE)
                                    PLANT_LAYOUT_MEMBERS(PLANT_LAYOUT_OFFSET)};

size_t plant_layout(size_t *out, size_t n)
{
    size_t all = sizeof layout / sizeof layout[0];
    for (size_t i = 0; i < n && i < all; i++)
        out[i] = layout[i];
    return all;
}

const char *plant_layout_names(void)
{
    return "sizeof(plant)" PLANT_LAYOUT_BLOCKS(PLANT_LAYOUT_SIZE_NAME)
        PLANT_LAYOUT_MEMBERS(PLANT_LAYOUT_OFFSET_NAME);
}
