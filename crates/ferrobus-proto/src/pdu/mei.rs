//! 0x2B Encapsulated Interface Transport: MEI type 0x0E Read Device Identification and any
//! other MEI type, such as 0x0D CANopen General Reference, carried as raw bytes
//! (MODBUS Application Protocol V1.1b3 §6.19–6.21).

use core::fmt;

use super::{Body, MAX_DATA_LEN, WireLen, check_quantity};
use crate::codes::{MeiType, ReadDeviceIdCode};
use crate::cursor::{Reader, Writer};
use crate::error::{BufferTooSmall, PduError};

const READ_DEVICE_ID: u8 = 0x0E;

/// A 0x2B request.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum MeiRequest<'a> {
    /// MEI 0x0E Read Device Identification.
    ReadDeviceId(ReadDeviceId),
    /// Any other MEI type (0x0D CANopen General Reference, vendor types).
    Other(RawMei<'a>),
}

/// A 0x2B response.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum MeiResponse<'a> {
    /// MEI 0x0E Read Device Identification.
    ReadDeviceId(DeviceIdentification<'a>),
    /// Any other MEI type, raw.
    Other(RawMei<'a>),
}

/// A 0x2B PDU of an MEI type other than 0x0E: the type and its data, uninterpreted.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct RawMei<'a> {
    mei_type: MeiType,
    data: &'a [u8],
}

impl<'a> RawMei<'a> {
    /// A raw MEI PDU; the type must not be 0x0E (that has its own types) and the data must
    /// fit in a PDU (at most 251 bytes).
    pub fn new(mei_type: MeiType, data: &'a [u8]) -> Result<Self, PduError> {
        if mei_type == MeiType::ReadDeviceIdentification {
            return Err(PduError::InvalidField { field: "MEI type", value: u16::from(READ_DEVICE_ID) });
        }
        check_quantity(data.len(), 0, MAX_DATA_LEN - 1)
            .map_err(|_| PduError::TooLong { len: data.len().saturating_add(2) })?;
        Ok(RawMei { mei_type, data })
    }

    /// The MEI type.
    pub fn mei_type(&self) -> MeiType {
        self.mei_type
    }

    /// The data after the MEI type.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }

    fn parse(mei: u8, r: &mut Reader<'a>) -> Result<Self, PduError> {
        RawMei::new(MeiType::from_u8(mei), r.rest())
    }

    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(self.mei_type.value())?;
        w.bytes(self.data)
    }
}

/// A 0x2B/0x0E request: read the objects of one category from `object_id` on, or one
/// specific object (§6.21).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ReadDeviceId {
    code: ReadDeviceIdCode,
    object_id: u8,
}

impl ReadDeviceId {
    /// A request with access `code` (basic, regular, extended or specific) from `object_id`.
    pub fn new(code: ReadDeviceIdCode, object_id: u8) -> Result<Self, PduError> {
        if let ReadDeviceIdCode::Other(v) = code {
            return Err(PduError::InvalidField { field: "read device id code", value: u16::from(v) });
        }
        Ok(ReadDeviceId { code, object_id })
    }

    /// The access category.
    pub fn code(&self) -> ReadDeviceIdCode {
        self.code
    }

    /// The first object wanted (or the one object, for `Specific`).
    pub fn object_id(&self) -> u8 {
        self.object_id
    }
}

impl<'a> Body<'a> for MeiRequest<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        match r.u8()? {
            READ_DEVICE_ID => {
                let code = ReadDeviceIdCode::from_u8(r.u8()?);
                Ok(MeiRequest::ReadDeviceId(ReadDeviceId::new(code, r.u8()?)?))
            }
            other => Ok(MeiRequest::Other(RawMei::parse(other, r)?)),
        }
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        match self {
            MeiRequest::ReadDeviceId(q) => {
                w.u8(READ_DEVICE_ID)?;
                w.u8(q.code.value())?;
                w.u8(q.object_id)
            }
            MeiRequest::Other(raw) => raw.emit(w),
        }
    }
    fn body_len(&self) -> usize {
        match self {
            MeiRequest::ReadDeviceId(_) => 3,
            MeiRequest::Other(raw) => raw.data.len().saturating_add(1),
        }
    }
    fn wire_len(head: &[u8]) -> WireLen {
        match head.first() {
            None => WireLen::NeedMore,
            Some(&READ_DEVICE_ID) => WireLen::Known(3),
            Some(_) => WireLen::Unknown,
        }
    }
}

/// One device identification object: an id and its value (ASCII for the standard objects).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct DeviceObject<'a> {
    /// Object id (0x00 VendorName, 0x01 ProductCode, …; see [`crate::codes::device_object`]).
    pub id: u8,
    /// The value, at most 255 bytes.
    pub value: &'a [u8],
}

/// The objects of a device identification response.
#[derive(Clone, Copy)]
pub struct DeviceObjects<'a> {
    repr: ObjectsRepr<'a>,
}

#[derive(Clone, Copy)]
enum ObjectsRepr<'a> {
    /// `count` objects as `id, len, value`, already validated.
    Wire {
        bytes: &'a [u8],
        count: u8,
    },
    Values(&'a [DeviceObject<'a>]),
}

impl<'a> DeviceObjects<'a> {
    /// A list of objects (at most 255, each value at most 255 bytes).
    pub fn new(objects: &'a [DeviceObject<'a>]) -> Result<Self, PduError> {
        check_quantity(objects.len(), 0, usize::from(u8::MAX))?;
        for o in objects {
            check_quantity(o.value.len(), 0, usize::from(u8::MAX))?;
        }
        Ok(DeviceObjects { repr: ObjectsRepr::Values(objects) })
    }

    /// Objects already laid out as `id, len, value` (by a slave building a response).
    pub(crate) fn from_wire(bytes: &'a [u8], count: u8) -> Self {
        DeviceObjects { repr: ObjectsRepr::Wire { bytes, count } }
    }

    /// Number of objects.
    pub fn len(&self) -> usize {
        match self.repr {
            ObjectsRepr::Wire { count, .. } => usize::from(count),
            ObjectsRepr::Values(v) => v.len(),
        }
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn byte_len(&self) -> usize {
        match self.repr {
            ObjectsRepr::Wire { bytes, .. } => bytes.len(),
            ObjectsRepr::Values(v) => v.iter().fold(0usize, |n, o| n.saturating_add(2).saturating_add(o.value.len())),
        }
    }

    /// The objects in order.
    pub fn iter(&self) -> impl Iterator<Item = DeviceObject<'a>> + 'a {
        let (mut rest, values) = match self.repr {
            ObjectsRepr::Wire { bytes, .. } => (bytes, &[][..]),
            ObjectsRepr::Values(v) => (&[][..], v),
        };
        let wire = core::iter::from_fn(move || {
            let mut r = Reader::new(rest, 0);
            let id = r.u8().ok()?;
            let len = usize::from(r.u8().ok()?);
            let value = r.bytes(len).ok()?;
            rest = r.rest();
            Some(DeviceObject { id, value })
        });
        wire.chain(values.iter().copied())
    }

    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        match self.repr {
            ObjectsRepr::Wire { bytes, .. } => w.bytes(bytes),
            ObjectsRepr::Values(v) => v.iter().try_for_each(|o| {
                w.u8(o.id)?;
                w.u8(u8::try_from(o.value.len()).unwrap_or(u8::MAX))?;
                w.bytes(o.value)
            }),
        }
    }
}

impl PartialEq for DeviceObjects<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl Eq for DeviceObjects<'_> {}

impl fmt::Debug for DeviceObjects<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

/// A 0x2B/0x0E response (§6.21).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct DeviceIdentification<'a> {
    code: ReadDeviceIdCode,
    conformity: u8,
    more_follows: bool,
    next_object_id: u8,
    objects: DeviceObjects<'a>,
}

impl<'a> DeviceIdentification<'a> {
    /// The most bytes of objects one response can carry (a 253-byte PDU less the function
    /// code and six header bytes).
    pub const MAX_OBJECT_BYTES: usize = MAX_DATA_LEN - 6;

    /// A response. `more_follows` says that another request from `next_object_id` will return
    /// more objects of the category. The objects must fit in one PDU.
    pub fn new(
        code: ReadDeviceIdCode,
        conformity: u8,
        more_follows: bool,
        next_object_id: u8,
        objects: DeviceObjects<'a>,
    ) -> Result<Self, PduError> {
        check_quantity(objects.byte_len(), 0, Self::MAX_OBJECT_BYTES)
            .map_err(|_| PduError::TooLong { len: objects.byte_len().saturating_add(7) })?;
        Ok(DeviceIdentification { code, conformity, more_follows, next_object_id, objects })
    }

    /// The access category of the request.
    pub fn code(&self) -> ReadDeviceIdCode {
        self.code
    }

    /// The device's conformity level (0x01–0x03, 0x81–0x83).
    pub fn conformity(&self) -> u8 {
        self.conformity
    }

    /// Whether more objects follow in a further transaction.
    pub fn more_follows(&self) -> bool {
        self.more_follows
    }

    /// Where the next transaction starts if more follow.
    pub fn next_object_id(&self) -> u8 {
        self.next_object_id
    }

    /// The objects.
    pub fn objects(&self) -> DeviceObjects<'a> {
        self.objects
    }
}

impl<'a> Body<'a> for MeiResponse<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let mei = r.u8()?;
        if mei != READ_DEVICE_ID {
            return Ok(MeiResponse::Other(RawMei::parse(mei, r)?));
        }
        let code = ReadDeviceIdCode::from_u8(r.u8()?);
        if let ReadDeviceIdCode::Other(v) = code {
            return Err(PduError::InvalidField { field: "read device id code", value: u16::from(v) });
        }
        let conformity = r.u8()?;
        let more_follows = match r.u8()? {
            0x00 => false,
            0xFF => true,
            other => {
                return Err(PduError::InvalidField { field: "more follows", value: u16::from(other) });
            }
        };
        let next_object_id = r.u8()?;
        let count = r.u8()?;
        let start = r.clone();
        for _ in 0..count {
            r.u8()?;
            let len = usize::from(r.u8()?);
            r.bytes(len)?;
        }
        let used = start.remaining().saturating_sub(r.remaining());
        let bytes = start.clone().bytes(used)?;
        let objects = DeviceObjects { repr: ObjectsRepr::Wire { bytes, count } };
        Ok(MeiResponse::ReadDeviceId(DeviceIdentification::new(
            code,
            conformity,
            more_follows,
            next_object_id,
            objects,
        )?))
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        match self {
            MeiResponse::ReadDeviceId(id) => {
                w.u8(READ_DEVICE_ID)?;
                w.u8(id.code.value())?;
                w.u8(id.conformity)?;
                w.u8(if id.more_follows { 0xFF } else { 0x00 })?;
                w.u8(id.next_object_id)?;
                w.u8(u8::try_from(id.objects.len()).unwrap_or(u8::MAX))?;
                id.objects.emit(w)
            }
            MeiResponse::Other(raw) => raw.emit(w),
        }
    }
    fn body_len(&self) -> usize {
        match self {
            MeiResponse::ReadDeviceId(id) => 6usize.saturating_add(id.objects.byte_len()),
            MeiResponse::Other(raw) => raw.data.len().saturating_add(1),
        }
    }
    fn wire_len(head: &[u8]) -> WireLen {
        match head.first() {
            None => return WireLen::NeedMore,
            Some(&READ_DEVICE_ID) => {}
            Some(_) => return WireLen::Unknown,
        }
        let Some(&count) = head.get(5) else {
            return WireLen::NeedMore;
        };
        let mut len = 6usize;
        for _ in 0..count {
            match head.get(len.saturating_add(1)) {
                Some(&n) => len = len.saturating_add(2).saturating_add(usize::from(n)),
                None => return WireLen::NeedMore,
            }
        }
        WireLen::Known(len)
    }
}
